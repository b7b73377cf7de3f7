"""The example notebook runs in a real kernel (nbclient, ipykernel): every cell without an
error, every figure drawn, and the numbers it shows those of the same calls in this process."""

from __future__ import annotations

import json

import pytest

import bitrock
from conftest import REPO

nbclient = pytest.importorskip("nbclient", reason="nbclient is part of the test extras")
import nbformat  # noqa: E402

NOTEBOOK = REPO / "examples" / "notebook.ipynb"


def test_the_example_notebook_runs_and_shows_the_librarys_numbers(demo, tmp_path) -> None:
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    errors = [o for o in outputs if o.output_type == "error"]
    assert not errors, errors
    figures = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(figures) == 5, "fit, probabilities, marginals, stability map, evidence"
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    # The HTML views: a record, a result, an evidence.
    html = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    assert any("bitrock.Result" in h for h in html) and any("bitrock.Evidence" in h for h in html)
    # Populations leave their lines in the cell's output.
    stream = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "population 0 (ε ∞): 1000 particles of" in stream
    # The run the notebook saved is the run this process makes with the same call.
    here = bitrock.abc(demo, particles=1000, seed=1, backend="cpu", progress=False)
    saved = json.loads((tmp_path / "run" / "run.json").read_text())
    assert saved["posterior"] == here.document["posterior"]
