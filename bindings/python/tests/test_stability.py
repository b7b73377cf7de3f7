"""Stability maps: the command line's numbers, the 1-DOF closed form, and refusals."""

from __future__ import annotations

import json
import time
import warnings

import numpy as np
import pytest

import bitrock
from conftest import run_cli

GRID = {"omega_rpm": "20:220:11", "wob_kn": "20:700:9"}


def assert_same_as_cli(maps, document) -> None:
    assert np.array_equal(maps["omega_rpm"].values, document["omega_rpm"])
    assert np.array_equal(maps["wob_kn"].values, document["wob_kn"])
    assert maps.attrs["critical_bit_damping_nms"] == document["critical_bit_damping_nms"]
    for law in maps["law"].values:
        cli_law = document["boundaries"][law]
        for key in ("map_wob_kn", "p_wob_kn"):
            expected = np.array([np.nan if v is None else v for v in cli_law[key]])
            assert np.array_equal(maps[key].sel(law=law).values, expected, equal_nan=True), (law, key)
        assert np.array_equal(maps["probability_unstable"].sel(law=law).values, np.array(document["probability_unstable"][law]))


def test_a_what_if_map_is_the_command_lines_and_the_closed_form(cli) -> None:
    maps = bitrock.stability(law="m2", params=[13, 6.5, 0.3], backend="cpu", **GRID)
    assert maps["probability_unstable"].dims == ("law", "omega_rpm", "wob_kn")
    assert maps["probability_unstable"].shape == (1, 11, 9)
    document = json.loads(
        run_cli(cli, "stability", "--law", "m2", "--params", "13,6.5,0.3", "--omega-rpm", GRID["omega_rpm"], "--wob-kn", GRID["wob_kn"], "--backend", "cpu", "--json").stdout
    )
    assert_same_as_cli(maps, document)
    # The 1-DOF boundary in closed form: W* = W_ref c_b* / (dT/dw at Ω), m2's slope
    # −(tsb − tcb) g exp(−g Ω) in N·m·s/rad.
    omega = maps["omega_rpm"].values * np.pi / 30
    slope = -(13e3 - 6.5e3) * 0.3 * np.exp(-0.3 * omega)
    expected_kn = 244.2e3 * maps.attrs["critical_bit_damping_nms"] / slope / 1e3
    np.testing.assert_allclose(maps["map_wob_kn"].sel(law="m2").values, expected_kn, rtol=1e-12)


def test_torques_in_newton_metres_read_as_kilonewton_metres_are_said() -> None:
    with pytest.warns(bitrock.BitrockWarning, match=r"tsb = 13000 kN·m lies beyond any drill bit's torque.*torque_unit"):
        wrong = bitrock.stability(law="m2", params=[13000, 6500, 0.3], backend="cpu", **GRID)
    with warnings.catch_warnings():
        warnings.simplefilter("error", bitrock.BitrockWarning)
        right = bitrock.stability(law="m2", params=[13000, 6500, 0.3], torque_unit="nm", backend="cpu", **GRID)
    # Read as kN·m the boundary sits a thousand times lower in weight on bit.
    np.testing.assert_allclose(right["map_wob_kn"].values, 1000 * wrong["map_wob_kn"].values, rtol=1e-12)


def test_a_runs_map_is_the_command_lines(cli, demo, tmp_path) -> None:
    result = bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=3, out=tmp_path / "run", progress=False)
    maps = bitrock.stability(result, samples=40, backend="cpu", **GRID)
    document = json.loads(
        run_cli(cli, "stability", "--run", str(tmp_path / "run"), "--samples", "40", "--omega-rpm", GRID["omega_rpm"], "--wob-kn", GRID["wob_kn"], "--backend", "cpu", "--json").stdout
    )
    assert_same_as_cli(maps, document)
    assert "mixture_p_wob_kn" in maps
    np.testing.assert_allclose(maps["probability"].sum(), 1.0, atol=1e-12)
    assert ((maps["probability_unstable"] >= 0) & (maps["probability_unstable"] <= 1)).all()


def test_the_fe_string_and_explicit_axes(cli) -> None:
    maps = bitrock.stability(law="m2", params=[13, 6.5, 0.3], structure="fe", dp_elements=20, omega_rpm=[40.0, 80.0, 120.0], wob_kn=[100.0, 300.0], backend="cpu")
    assert maps.attrs["structure"] == "fe"
    document = json.loads(
        run_cli(cli, "stability", "--law", "m2", "--params", "13,6.5,0.3", "--structure", "fe", "--dp-elements", "20", "--omega-rpm", "40:120:3", "--wob-kn", "100:300:2", "--backend", "cpu", "--json").stdout
    )
    assert_same_as_cli(maps, document)


def test_a_run_in_memory_maps_as_its_saved_twin(demo, tmp_path) -> None:
    settings = {"particles": 300, "seed": 11, "backend": "cpu", "max_populations": 3, "progress": False}
    saved = bitrock.stability(bitrock.abc(demo, out=tmp_path / "run", **settings), samples=40, backend="cpu", **GRID)
    in_memory = bitrock.stability(bitrock.abc(demo, **settings), samples=40, backend="cpu", **GRID)
    assert list(in_memory["law"].values) == list(saved["law"].values)
    np.testing.assert_allclose(in_memory["probability"], saved["probability"], rtol=1e-12)
    # The particles travel in the record's kN·m and back: boundaries to that rounding.
    for key in ("map_wob_kn", "p_wob_kn", "mixture_p_wob_kn"):
        np.testing.assert_allclose(in_memory[key], saved[key], rtol=1e-9)
    assert np.array_equal(in_memory["probability_unstable"], saved["probability_unstable"])


def test_refusals_name_their_argument() -> None:
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.stability()
    assert caught.value.argument == "source"
    with pytest.raises(bitrock.InputError, match="alpha: applies to `structure` fe only") as caught:
        bitrock.stability(law="m2", params=[13, 6.5, 0.3], alpha=0.1)
    assert caught.value.argument == "alpha"
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.stability(law="m2", params=[13, 6.5, 0.3], omega_rpm=[50.0, float("nan")])
    assert caught.value.argument == "omega_rpm"
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.stability(law="m2", params=[13, 6.5])
    assert caught.value.argument == "params"


def test_the_selection_check_is_the_command_lines(cli, demo, tmp_path) -> None:
    import shutil

    bitrock.abc(demo, particles=150, seed=11, backend="cpu", laws=["m2", "m3"], max_populations=3, out=tmp_path / "py", progress=False)
    shutil.copytree(tmp_path / "py", tmp_path / "cli")
    seen: list[tuple[int, int]] = []
    inside = [0]

    def progress(done: int, total: int) -> None:
        # Replicates finish on several threads; the sleep lets the interpreter switch to
        # another thread's call, if one could be made meanwhile.
        inside[0] += 1
        assert inside[0] == 1, "two progress calls at once"
        time.sleep(0.05)
        seen.append((done, total))
        inside[0] -= 1

    matrix = bitrock.check_selection(tmp_path / "py", replicates=2, backend="cpu", progress=progress)
    assert matrix.shape == (2, 2) and list(matrix.index) == ["m2", "m3"] and list(matrix.columns) == ["m2", "m3"]
    np.testing.assert_allclose(matrix.sum(axis=1), 1.0, atol=1e-9)
    assert seen == [(1, 4), (2, 4), (3, 4), (4, 4)]
    assert (tmp_path / "py" / "selection").is_dir()
    document = json.loads(run_cli(cli, "check-selection", str(tmp_path / "cli"), "--replicates", "2", "--backend", "cpu", "--json", "-q").stdout)
    for ours, theirs in zip(matrix.attrs["document"]["rows"], document["rows"]):
        assert ours["mean_probability"] == theirs["mean_probability"]
        assert ours["first_share"] == theirs["first_share"]
        assert ours["verdict"] == theirs["verdict"]
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.check_selection(tmp_path / "py", replicates=0)
    assert caught.value.argument == "replicates"
