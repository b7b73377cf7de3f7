"""Least-squares fits: the DataFrame, its agreement with `bitrock fit --json`, and refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

import bitrock
from conftest import run_cli


def test_the_fit_table_holds_every_parameter_of_every_law(demo: bitrock.Record) -> None:
    table = bitrock.fit(demo)
    assert list(table.columns) == ["law", "parameter", "estimate", "std_error", "unit", "rho", "validation_rho", "warnings"]
    assert table.groupby("law").size().to_dict() == {"m1": 4, "m2": 3, "m3": 6, "m4": 4}
    assert (table["rho"] > 0).all() and (table["rho"] < 0.02).all()
    m2 = table[table["law"] == "m2"].set_index("parameter")
    assert m2.loc["tsb", "unit"] == "kN·m"


def test_the_fit_is_the_command_lines(cli, demo: bitrock.Record) -> None:
    document = json.loads(run_cli(cli, "fit", "--json").stdout)
    table = bitrock.fit(demo)
    for f in document["fits"]:
        estimates = table[table["law"] == f["law"]]["estimate"].to_numpy()
        assert np.array_equal(estimates, np.array(f["params"], dtype=float))


def test_laws_and_bounds(demo: bitrock.Record) -> None:
    only = bitrock.fit(demo, laws=["m2"], bounds=False)
    assert set(only["law"]) == {"m2"}
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.fit(demo, w_ref_kn=200.0)
    assert caught.value.argument == "w_ref_kn"
    assert "`scale_by_wob`" in str(caught.value)
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.fit(demo, laws=["m9"])
    assert caught.value.argument == "laws"


def test_scaling_by_weight_on_bit_changes_the_fit(demo: bitrock.Record) -> None:
    plain = bitrock.fit(demo, laws=["m2"])
    scaled = bitrock.fit(demo, laws=["m2"], scale_by_wob=True, w_ref_kn=200.0)
    assert not np.array_equal(plain["estimate"].to_numpy(), scaled["estimate"].to_numpy())


def test_a_simulated_record_is_the_command_lines_and_fits_back(cli, tmp_path) -> None:
    import pandas as pd

    frame = bitrock.simulate("m2", omega_rpm=50, duration_s=30, settle_s=10, noise_torque_knm=0.3, seed=4)
    run_cli(cli, "simulate", "--law", "m2", "--omega-rpm", "50", "--duration-s", "30", "--settle-s", "10", "--noise-torque-knm", "0.3", "--seed", "4", "--out", str(tmp_path / "rig.csv"))
    assert frame.equals(pd.read_csv(tmp_path / "rig.csv"))
    assert list(frame.columns) == ["time_s", "bit_speed_rpm", "torque_knm", "wob_kn"]
    assert len(frame) == 30 * 50
    # The paper's m2 comes back from its own record (stick-slip at 50 rpm, 0.3 kN·m noise).
    table = bitrock.fit(bitrock.read_record(frame), laws=["m2"]).set_index("parameter")
    np.testing.assert_allclose(table.loc[["tsb", "tcb", "g"], "estimate"], [13.0, 6.5, 0.3], rtol=0.05)
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.simulate("m2", omega_rpm=50, params=[13, 6.5])
    assert caught.value.argument == "params"
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.simulate("m2", omega_rpm=50, initial="sideways")
    assert caught.value.argument == "initial"
    # N·m values given as kN·m: simulated, but said.
    with pytest.warns(bitrock.BitrockWarning, match=r"tsb = 13000 kN·m lies beyond any drill bit's torque.*param_torque_unit"):
        bitrock.simulate("m2", omega_rpm=50, params=[13000, 6500, 0.3], duration_s=2, settle_s=1)
