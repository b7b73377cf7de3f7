"""Shared fixtures: the repository's demo record, the command-line binary the identity tests
compare against, and a small run."""

from __future__ import annotations

import os
import pathlib
import subprocess

import pytest

import bitrock

REPO = pathlib.Path(__file__).resolve().parents[3]
DEMO_CSV = REPO / "data" / "demo.csv"


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The ``bitrock`` binary: ``BITROCK_BIN``, else the repository's release build. Missing is
    a failure, not a skip: the identity tests are the point of the suite."""
    path = pathlib.Path(os.environ.get("BITROCK_BIN", REPO / "target" / "release" / "bitrock"))
    assert path.is_file(), f"no bitrock binary at {path}: build it (cargo build --release) or set BITROCK_BIN"
    return path


def run_cli(cli: pathlib.Path, *args: str, cwd: pathlib.Path | None = None) -> subprocess.CompletedProcess[str]:
    """Runs the command line, failing the test with its standard error when it fails."""
    done = subprocess.run([str(cli), *args], capture_output=True, text=True, cwd=cwd, env={**os.environ, "NODEVICE_SELECT": "1"})
    assert done.returncode == 0, f"bitrock {' '.join(args)} exited {done.returncode}: {done.stderr}"
    return done


@pytest.fixture(scope="session")
def demo() -> bitrock.Record:
    return bitrock.read_record()


@pytest.fixture(scope="session")
def small_run(demo: bitrock.Record) -> bitrock.Result:
    """A rejection run in memory on the demo record: 300 particles, seed 11, CPU."""
    return bitrock.abc(demo, particles=300, seed=11, backend="cpu", progress=False)
