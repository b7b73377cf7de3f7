"""The README's example script runs end to end."""

from __future__ import annotations

import os
import subprocess
import sys

from conftest import REPO


def test_the_quickstart_example_runs(tmp_path) -> None:
    figure = tmp_path / "fit.png"
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / "python_quickstart.py"), str(REPO / "data" / "demo.csv"), str(figure)],
        capture_output=True,
        text=True,
        env={**os.environ, "MPLBACKEND": "Agg", "NODEVICE_SELECT": "1"},
    )
    assert done.returncode == 0, done.stderr
    assert "population" in done.stdout and "m2" in done.stdout
    assert figure.stat().st_size > 1000
