"""The same numbers as the command line: with the same record, seed and settings, Python and
`bitrock abc` give bit-identical particles, and each reads the other's run directory."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import bitrock
from conftest import DEMO_CSV, run_cli


def assert_same_particles(a: bitrock.Result, b: bitrock.Result) -> None:
    assert len(a.populations) == len(b.populations)
    for g in range(len(a.populations)):
        pa, pb = a.particles(g), b.particles(g)
        assert pa.keys() == pb.keys()
        for law in pa:
            for x, y in zip(pa[law][1:], pb[law][1:]):
                assert np.array_equal(x, y), (g, law)


@pytest.mark.parametrize(
    ("flags", "settings"),
    [
        (["--seed", "11"], {"seed": 11}),
        (["--sampler", "smc", "--seed", "4", "--max-populations", "4"], {"sampler": "smc", "seed": 4, "max_populations": 4}),
        (["--mode", "paper", "--laws", "m2,m3", "--delta", "0.3", "--seed", "8"], {"mode": "paper", "laws": ["m2", "m3"], "delta": 0.3, "seed": 8}),
    ],
)
def test_python_and_the_command_line_give_the_same_particles(cli, tmp_path, flags, settings) -> None:
    run_cli(cli, "abc", str(DEMO_CSV), "--particles", "300", "--backend", "cpu", "--out", str(tmp_path / "cli"), *flags)
    from_cli = bitrock.open_run(tmp_path / "cli")
    record = bitrock.read_record(DEMO_CSV)
    from_python = bitrock.abc(record, particles=300, backend="cpu", out=tmp_path / "py", progress=False, **settings)
    assert_same_particles(from_cli, from_python)
    in_memory = bitrock.abc(record, particles=300, backend="cpu", progress=False, **settings)
    assert_same_particles(from_cli, in_memory)
    assert from_cli.document["config"] == from_python.document["config"]
    # The command line reads the Python run: its export is the CLI run's, byte for byte.
    run_cli(cli, "export", str(tmp_path / "cli"), "-o", str(tmp_path / "cli.csv"))
    run_cli(cli, "export", str(tmp_path / "py"), "-o", str(tmp_path / "py.csv"))
    assert (tmp_path / "cli.csv").read_bytes() == (tmp_path / "py.csv").read_bytes()


def test_a_dataframe_record_runs_as_its_csv_does(cli, tmp_path) -> None:
    run_cli(cli, "abc", str(DEMO_CSV), "--particles", "300", "--backend", "cpu", "--seed", "21", "--out", str(tmp_path / "cli"))
    frame = pd.read_csv(DEMO_CSV)
    run = bitrock.abc(bitrock.read_record(frame), particles=300, seed=21, backend="cpu", progress=False)
    assert_same_particles(bitrock.open_run(tmp_path / "cli"), run)


def test_the_command_line_continues_a_python_run(cli, demo: bitrock.Record, tmp_path) -> None:
    whole = bitrock.abc(demo, particles=300, seed=13, backend="cpu", progress=False)
    bitrock.abc(demo, particles=300, seed=13, backend="cpu", max_populations=2, out=tmp_path / "py", progress=False)
    run_cli(cli, "abc", "--resume", str(tmp_path / "py"), "--max-populations", "30")
    assert_same_particles(whole, bitrock.open_run(tmp_path / "py"))
