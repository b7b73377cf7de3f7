"""A law of the user's own from a law file: loaded once, named like m1…m4 in fits and runs,
stored with the run, and shipped to workers with the problem."""

from __future__ import annotations

import concurrent.futures
import multiprocessing

import pytest

import bitrock
from conftest import REPO
from test_distributed import assert_same_store

STRIBECK = REPO / "examples" / "laws" / "stribeck.toml"


def test_a_law_file_is_loaded_and_fitted_with_the_built_in_laws(demo: bitrock.Record) -> None:
    assert bitrock.load_law(STRIBECK) == "stribeck"
    # Loading it again is harmless: the same law.
    assert bitrock.load_law(STRIBECK) == "stribeck"
    fits = bitrock.fit(demo, laws=["m2", "stribeck"])
    assert list(dict.fromkeys(fits["law"])) == ["m2", "stribeck"]
    stribeck = fits[fits["law"] == "stribeck"]
    assert list(stribeck["parameter"]) == ["ts", "tc", "vs", "cv"]
    assert list(stribeck["unit"]) == ["kN·m", "kN·m", "rad/s", "kN·m·s/rad"]
    # The record is in kN·m: the static torque is about the record's, 9-10 kN·m.
    ts = float(stribeck[stribeck["parameter"] == "ts"]["estimate"].iloc[0])
    assert 8.0 < ts < 11.0, ts


def test_a_bad_law_file_raises_an_input_error_naming_line_and_column(tmp_path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\ntorque = "r * (k + w)"\n[[parameter]]\nname = "k"\nunit = "N·m"\n')
    with pytest.raises(bitrock.InputError, match=r"bad\.toml:2:11: torque: adding w to k"):
        bitrock.load_law(bad)
    with pytest.raises(bitrock.InputError, match="unknown law 'nolaw'"):
        bitrock.fit(bitrock.read_record(), laws=["nolaw"])


def test_a_run_with_a_law_file_on_a_process_pool_gives_the_one_process_store(demo, tmp_path) -> None:
    bitrock.load_law(STRIBECK)
    settings = {"particles": 400, "seed": 3, "backend": "cpu", "progress": False, "laws": ["m2", "m3", "stribeck"]}
    one = bitrock.abc(demo, out=tmp_path / "one", **settings)
    assert "stribeck" in one.laws
    # Spawned workers have never read the file: the problem carries its text.
    with concurrent.futures.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        bitrock.abc(demo, out=tmp_path / "pool", executor=pool, **settings)
    assert_same_store(tmp_path / "one", tmp_path / "pool")
    # And the run reads back with its law.
    again = bitrock.open_run(tmp_path / "one")
    assert "stribeck" in list(again.model_probabilities.columns)
