"""Laws from a surface record, judged on records of an independent integrator (scipy's LSODA
with its own stick handling, the twin of test_strings.py): the surface channels inferred from,
the bit's speed kept as the truth."""

import json
import os

import numpy as np
import pandas as pd
import pytest
from test_strings import PAPER, RPM, STUCK_RAD_S, after_change, cycles_at, integrate, one_dof, torque_law

import bitrock
from conftest import run_cli

M2_NM = [13000.0, 6500.0, 0.3]


def twin_record(path, rpm=60.0, seconds=300.0, noise_nm=200.0, seed=5, mwd_hz=None, string=(), law="m2", params=None):
    """`law` (m2 by default) at `params` (N·m; the paper's estimate by default) at `rpm`: a
    surface record at 1 Hz (top-drive speed, surface torque with white noise, weight on bit)
    written to `path`, and the bit's true speeds at 1 Hz. With `mwd_hz`, the string is sampled
    that finely and the record also holds an MWD tool's downhole minimum and maximum bit speed
    since the sample before (rpm). `string`: the 1-DOF string's inertia, natural frequency and
    damping ratio (the paper's by default)."""
    if params is None:
        values, torques = PAPER[law]
        params = [v * 1000.0 if torque else v for v, torque in zip(values, torques)]
    chain = one_dof(*string)
    omega = rpm * RPM
    t0 = torque_law(law)(params, omega)
    y = np.array([t0 / chain[1][0], omega + 0.1 * omega])
    fine = mwd_hz or 1.0
    step = int(round(fine))
    surface = []
    speeds, _ = integrate(chain, law, params, omega, 1.0, (y, False, 1.0), 60.0, seconds, sample_hz=fine, surface=surface)
    surface = np.array(surface)[::step]
    noise = np.random.default_rng(seed).normal(0.0, noise_nm, len(surface))
    columns = {
        "time_s": np.arange(len(surface), dtype=float),
        "top_drive_rpm": rpm,
        "surface_torque_knm": (surface + noise) / 1000.0,
        "wob_kn": 244.2,
    }
    if mwd_hz:
        # Sample k's window: the fine samples after sample k - 1, up to and with sample k.
        windows = [speeds[max(k * step - step + 1, 0) : k * step + 1] for k in range(len(surface))]
        columns["downhole_min_rpm"] = [w.min() / RPM for w in windows]
        columns["downhole_max_rpm"] = [w.max() / RPM for w in windows]
    pd.DataFrame(columns).to_csv(path, index=False)
    return speeds[::step]


SMALL = dict(particles=300, max_populations=6, pilot=300, check_replicates=4, predictive_draws=40, advice=False)


def test_an_independent_string_s_surface_gives_its_torques_and_stuck_share(tmp_path):
    path = tmp_path / "rig.csv"
    speeds = twin_record(path)
    true_share = float(np.mean(np.abs(speeds) < STUCK_RAD_S))
    assert true_share > 0.4
    result = bitrock.surface(path, laws=["m2"], seed=2, **SMALL)
    assert result["cycle"]["period_s"] == pytest.approx(9.75, abs=0.3)
    (m2,) = result["laws"]
    for p, truth in zip(m2["params"], M2_NM):
        covered = p["q05"] <= truth <= p["q95"]
        assert covered or (p["name"] == "g" and not p["identified"]), p
    stuck = result["at_the_bit"]["stuck_share"]
    assert abs(stuck[1] - true_share) <= 0.05, (stuck, true_share)
    band = np.array(result["at_the_bit"]["speed_rpm"])
    rpm = speeds / RPM
    inside = np.mean((band[:, 0] - 0.5 <= rpm) & (rpm <= band[:, 2] + 0.5))
    assert inside >= 0.85, inside
    assert len(result["time_s"]) == len(rpm)


def test_the_way_out_along_g_s_spread_gets_the_independent_string_s_bit_out(tmp_path):
    # The twin's surface leaves m2's g to the prior; the strings drawn from the posterior end
    # the stick-slip at a speed the twin's bit, stuck at 60 rpm, does not take (95 rpm: stuck
    # 31-38 % of the time), and the result says so. Every string along the posterior's spread
    # of g ending it: the speed and the weight found there (measured: 155 rpm, 73 kN), applied
    # at four phases of the twin's cycle, get its bit out.
    path = tmp_path / "rig.csv"
    twin_record(path)
    result = bitrock.surface(path, laws=["m2"], seed=2, **dict(SMALL, advice=True))
    at = result["at_the_bit"]
    assert "leaves m2's g to the prior" in at["advice"], at["advice"]
    spread_advice = at["spread_advice"]
    assert spread_advice["open"] == ["m2's g"]
    chain = one_dof()
    cycles = cycles_at(chain, "m2", M2_NM, 60.0 * RPM, 1.0, phases=4)
    assert all(share > 0.3 for share, _ in cycles), cycles
    drawn = float(at["advice"].split("raise the top-drive speed to ")[1].split(" ")[0])
    assert drawn < spread_advice["speed_rpm"], (drawn, spread_advice)
    for share, state in cycles:
        assert after_change(chain, "m2", M2_NM, drawn * RPM, 1.0, state) > 0.2
        assert after_change(chain, "m2", M2_NM, spread_advice["speed_rpm"] * RPM, 1.0, state) < 0.01
        assert after_change(chain, "m2", M2_NM, 60.0 * RPM, spread_advice["wob_kn"] / 244.2, state) < 0.01


def test_on_an_independent_softer_string_inferred_with_the_law_the_spread_s_way_out_gets_its_bit_out(tmp_path):
    # The twin's m2 on a softer string than the paper's (ω_n 0.6 rad/s), the string inferred
    # with the law, each advice sample simulated on its own string: the drawn strings' speed
    # leaves the twin's bit stuck (measured: 110 rpm, stuck 27-43 % of the time at four phases
    # of its cycle); the speed and weight along g's spread (160 rpm, 61 kN) get it out.
    path = tmp_path / "rig.csv"
    soft = (383.33, 0.6, 0.25)
    twin_record(path, string=soft)
    result = bitrock.surface(path, laws=["m2"], seed=2, omega_n_rad_s=(0.4, 1.8), damping_ratio=0.25, advice=True)
    omega = result["string"]["omega_n_rad_s"]
    assert omega["q05"] <= 0.6 <= omega["q95"], omega
    at = result["at_the_bit"]
    spread_advice = at["spread_advice"]
    assert spread_advice["open"] == ["m2's g"], at
    chain = one_dof(*soft)
    cycles = cycles_at(chain, "m2", M2_NM, 60.0 * RPM, 1.0, phases=4)
    assert all(share > 0.3 for share, _ in cycles), cycles
    drawn = float(at["advice"].split("raise the top-drive speed to ")[1].split(" ")[0])
    assert max(after_change(chain, "m2", M2_NM, drawn * RPM, 1.0, state) for _, state in cycles) > 0.2
    for _, state in cycles:
        assert after_change(chain, "m2", M2_NM, spread_advice["speed_rpm"] * RPM, 1.0, state) < 0.01
        assert after_change(chain, "m2", M2_NM, 60.0 * RPM, spread_advice["wob_kn"] / 244.2, state) < 0.01


# The GPU's f32 strings part ways with the CPU's f64 ones where a candidate's cycle is
# irregular, so a run on each backend is its own realisation: at SMALL's budget the GPU's run of
# seed 2 stops further from the record (measured on lavapipe, 2026-12-01: ε 2.37 against the
# CPU's 0.94, P(m2) 0.88; seeds 3 and 4 give 0.97 and 1.0), at 600 particles and 8 populations
# P(m2) = 1.0 for seeds 2, 3 and 4.
ON_THE_GPU = pytest.param(
    "gpu",
    {**SMALL, "particles": 600, "max_populations": 8},
    marks=pytest.mark.skipif(os.environ.get("BITROCK_SKIP_GPU_TESTS") == "1", reason="BITROCK_SKIP_GPU_TESTS=1"),
)


@pytest.mark.parametrize("backend, budget", [("cpu", SMALL), ON_THE_GPU])
def test_an_independent_string_s_mwd_extremes_tell_its_held_bit_from_a_creeping_one(tmp_path, backend, budget):
    # The LSODA twin's m2 (its own stick handling), sampled at 50 Hz for the MWD's minimum and
    # maximum: m1, whose bit creeps, is left no probability, and the stuck share is the twin's.
    path = tmp_path / "mwd.csv"
    speeds = twin_record(path, mwd_hz=50.0)
    true_share = float(np.mean(np.abs(speeds) < STUCK_RAD_S))
    result = bitrock.surface(path, laws=["m1", "m2"], seed=2, backend=backend, **budget)
    assert result["backend"].lower().startswith(backend), result["backend"]
    probability = {law["law"]: law["probability"] for law in result["laws"]}
    assert probability["m2"] > 0.9, result["laws"]
    stuck = result["at_the_bit"]["stuck_share"]
    assert abs(stuck[1] - true_share) <= 0.05, (stuck, true_share)


def test_from_an_independent_string_s_surface_alone_a_creeping_bit_is_told_from_a_held_one(tmp_path):
    # m1 (no static torque: its bit creeps where m2's is held) and m2 at 40 rpm on the paper's
    # string, ten minutes at 1 Hz from the twin: the held bit lets the string wind up at k·Ω,
    # the creeping one slower. The noise is read on the wind-ups and the check never calls the
    # other law. m2 cannot wind up slower, so on m1's record m1 leads; m1 with a tanh steep
    # enough nearly holds its bit, so on m2's record at 1 Hz the two stay close (m2 first in 7
    # of 10 of bitrock's own records at the command's budget).
    rates = {}
    for law in ("m1", "m2"):
        path = tmp_path / f"{law}.csv"
        twin_record(path, rpm=40.0, seconds=600.0, seed=3, law=law)
        result = bitrock.surface(path, laws=["m1", "m2"], seed=2, **SMALL)
        assert result["noise"]["how"] == "wind_up"
        assert result["noise"]["sd_nm"] == pytest.approx(200.0, abs=40.0)
        probability = {row["law"]: row["probability"] for row in result["laws"]}
        if law == "m1":
            assert probability["m1"] > 0.7, probability
        assert result["check"]["decided"] in (None, law), result["check"]["verdict"]
        rates[law] = result["observed"][result["summary_names"].index("wind_up_nm_s")]
    # k·Ω = 277 N·m/rad × 4.19 rad/s = 1,160 N·m/s where the bit is held.
    assert rates["m2"] == pytest.approx(1160.0, abs=40.0)
    assert rates["m1"] < 0.97 * rates["m2"], rates


def test_an_independent_string_s_natural_frequency_and_damping_are_inferred_with_the_law(tmp_path):
    # The twin's string stiffer and less damped than the paper's (ω_n 1.2 rad/s, ξ 0.15): given
    # as bounds, both are inferred with the law, and their intervals hold the twin's.
    path = tmp_path / "rig.csv"
    speeds = twin_record(path, string=(383.33, 1.2, 0.15))
    true_share = float(np.mean(np.abs(speeds) < STUCK_RAD_S))
    result = bitrock.surface(
        path, laws=["m2"], seed=2, omega_n_rad_s=(0.6, 1.8), damping_ratio=(0.05, 0.5), **SMALL
    )
    string = result["string"]
    assert string["inferred"]
    for name, truth in (("omega_n_rad_s", 1.2), ("damping_ratio", 0.15)):
        p = string[name]
        assert p["q05"] <= truth <= p["q95"], (name, p)
    assert string["omega_n_rad_s"]["identified"], string
    k = string["stiffness_knm_per_rad"][1]
    assert k == pytest.approx(383.33 * string["omega_n_rad_s"]["median"] ** 2 / 1000.0, rel=1e-12)
    stuck = result["at_the_bit"]["stuck_share"]
    assert abs(stuck[1] - true_share) <= 0.1, (stuck, true_share)
    # A given value holds: every quantile is it.
    held = bitrock.surface(path, laws=["m2"], seed=2, omega_n_rad_s=(0.6, 1.8), damping_ratio=0.15, **SMALL)
    assert held["string"]["damping_ratio"]["given"] and not held["string"]["omega_n_rad_s"]["given"]
    assert {held["string"]["damping_ratio"][q] for q in ("q05", "median", "q95")} == {0.15}
    with pytest.raises(bitrock.InputError, match="omega_n_rad_s") as caught:
        bitrock.surface(path, laws=["m2"], omega_n_rad_s=(1.8, 0.6))
    assert caught.value.argument == "omega_n_rad_s"


def test_a_simulated_surface_record_goes_through_and_bad_settings_name_their_argument(tmp_path):
    frame = bitrock.simulate("m2", omega_rpm=60, duration_s=120, settle_s=60, sample_hz=1, channels="surface", seed=2)
    assert list(frame.columns) == ["time_s", "top_drive_rpm", "surface_torque_knm", "wob_kn"]
    path = tmp_path / "surface.csv"
    frame.to_csv(path, index=False)
    small = dict(SMALL, particles=100, max_populations=2, pilot=100, check_replicates=2, predictive_draws=10)
    result = bitrock.surface(path, laws=["m1", "m2"], **small)
    assert {law["law"] for law in result["laws"]} == {"m1", "m2"}
    assert result["noise"]["how"] in ("estimated", "wind_up", "bounded")
    with pytest.raises(bitrock.InputError, match="pilot"):
        bitrock.surface(path, laws=["m2"], pilot=10)
    with pytest.raises(bitrock.InputError, match="top_drive_col"):
        bitrock.surface(path, top_drive_col="rotary")
    with pytest.raises(bitrock.InputError, match="channels"):
        bitrock.simulate("m2", omega_rpm=60, channels="downhole")


def test_an_mwd_tool_s_downhole_extremes_are_read_and_compared(tmp_path):
    frame = bitrock.simulate("m2", omega_rpm=60, duration_s=120, settle_s=60, sample_hz=1, channels="mwd", seed=2)
    assert list(frame.columns)[-2:] == ["downhole_min_rpm", "downhole_max_rpm"]
    # m2 holds its bit: the least speed since the sample before is 0 at most samples, while
    # the greatest is the slips' (m2 at 60 rpm peaks near three times the top drive's speed).
    assert (frame["downhole_min_rpm"] == 0.0).mean() > 0.4
    assert frame["downhole_max_rpm"].max() > 120.0
    path = tmp_path / "mwd.csv"
    frame.to_csv(path, index=False)
    small = dict(SMALL, particles=100, max_populations=2, pilot=100, check_replicates=2, predictive_draws=10)
    result = bitrock.surface(path, laws=["m2"], downhole_window_s=2.0, **small)
    assert result["summary_names"][-4:] == [
        "downhole_min_mean_rad_s",
        "downhole_held_share",
        "downhole_max_mean_rad_s",
        "downhole_max_q90_rad_s",
    ]
    assert "over 2 sample(s)" in result["roles"]
    with pytest.raises(bitrock.InputError, match="downhole_window_s"):
        bitrock.surface(path, laws=["m2"], downhole_window_s=0.5)
    with pytest.raises(bitrock.InputError, match="downhole_min_col"):
        bitrock.surface(path, laws=["m2"], downhole_min_col="dh_min")


def test_every_surface_setting_is_a_keyword_and_a_bad_value_is_refused_by_name(tmp_path):
    import inspect

    fields = bitrock._bitrock.settings_fields("surface")
    assert {"pilot", "check_replicates", "noise_sd_knm", "prior_file", "advice", "seed"} <= set(fields)
    keywords = inspect.signature(bitrock.surface).parameters
    assert [f for f in fields if f not in keywords] == []
    path = tmp_path / "surface.csv"
    bitrock.simulate("m2", omega_rpm=60, duration_s=30, settle_s=10, sample_hz=1, channels="surface", seed=2).to_csv(
        path, index=False
    )
    # Refused by the gate, before any simulation, naming the keyword.
    with pytest.raises(bitrock.InputError, match="noise_sd_knm") as caught:
        bitrock.surface(path, laws=["m2"], noise_sd_knm=-0.1)
    assert caught.value.argument == "noise_sd_knm"
    with pytest.raises(bitrock.InputError, match="particles") as caught:
        bitrock.surface(path, laws=["m2"], particles="many")
    assert caught.value.argument == "particles"


def test_a_surface_directory_is_continued_to_the_run_it_would_have_been(cli, tmp_path):
    path = tmp_path / "surface.csv"
    bitrock.simulate(
        "m2", omega_rpm=60, duration_s=120, settle_s=60, sample_hz=1, channels="surface", noise_torque_knm=0.2, seed=7
    ).to_csv(path, index=False)
    small = dict(
        laws=["m1", "m2"],
        particles=150,
        pilot=100,
        check_replicates=4,
        predictive_draws=40,
        advice=False,
        backend="cpu",
        seed=11,
    )
    out = tmp_path / "run"
    first = bitrock.surface(path, max_populations=2, out=out, **small)
    assert first["populations"] == 2
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "bit.csv",
        "populations.bin",
        "posterior.csv",
        "record.csv",
        "surface-job.json",
        "surface.json",
    ]
    read = bitrock.read_surface(out)
    assert read == first
    continued = bitrock.resume_surface(out, max_populations=3)
    whole = bitrock.surface(path, max_populations=3, **small)
    for result in (continued, whole):
        result.pop("seconds")
    assert continued["populations"] == 3
    assert continued == whole
    # Checked again with more records per law, the populations as they were.
    rechecked = bitrock.resume_surface(out, max_populations=3, check_replicates=6)
    assert [row["replicates"] for row in rechecked["check"]["rows"]] == [6, 6]
    assert rechecked["epsilons"] == whole["epsilons"]
    # check_selection of the directory: the check made again, as a matrix of shares.
    matrix = bitrock.check_selection(out, replicates=5)
    document = bitrock.read_surface(out)
    assert matrix.attrs["document"] == document["check"]
    assert list(matrix.index) == ["m1", "m2"] and list(matrix.columns) == ["m1", "m2"]
    assert matrix.sum(axis=1).tolist() == pytest.approx([1.0, 1.0])
    for row in document["check"]["rows"]:
        assert row["replicates"] == 5
        assert matrix.loc[row["law"], row["law"]] == pytest.approx(row["recognised"])
    assert document["epsilons"] == whole["epsilons"]
    # Its posterior mapped as `bitrock stability --run` maps it: at the W_ref its laws hold at,
    # with the advice from the bit its surface implies.
    maps = bitrock.stability(out)
    theirs = json.loads(run_cli(cli, "stability", "--run", str(out), "--json").stdout)
    for i, law in enumerate(maps.coords["law"].values):
        grid = np.array(theirs["probability_unstable"][law], dtype=float)
        np.testing.assert_array_equal(maps["probability_unstable"].values[i], grid)
    assert maps.attrs["record_advice"] == {"record": theirs["record"], "advice": theirs["advice"]}
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.check_selection(out, batch=2)
    assert caught.value.argument == "batch"
    with pytest.raises(bitrock.InputError, match="resume_surface") as caught:
        bitrock.surface(path, max_populations=2, out=out, **small)
    assert caught.value.argument == "out"
    with pytest.raises(bitrock.InputError, match="holds no surface run") as caught:
        bitrock.resume_surface(tmp_path)
    assert caught.value.argument == "directory"
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.resume_surface(out, backend="abacus")
    assert caught.value.argument == "backend"


def test_a_watch_of_an_independent_string_s_surface_implies_its_bit_window_by_window(cli, tmp_path):
    # The independent integrator's m2 at 60 rpm, five minutes of surface channels at 1 Hz,
    # watched in two windows of 150 s: each window's laws through simulated strings, its model
    # choice checked, and the bit it implies against the twin's own bit.
    path = tmp_path / "rig.csv"
    speeds = twin_record(path)
    watch = bitrock.watch(path, laws=["m2", "m3"], window_s=150, step_s=150, backend="cpu", seed=4)
    updates = list(watch)
    assert len(updates) == 2
    for u in updates:
        assert u.uninformative is None, u
        assert u.check["verdict"], u.check
        start, end = int(u.start_s), int(u.end_s)
        truth = float(np.mean(np.abs(speeds[start:end]) < STUCK_RAD_S))
        assert truth > 0.4
        assert abs(u.advice["stuck_share"] - truth) <= 0.06, (u.advice, truth)
        assert u.advice["stick_slip_now"] and u.advice["escape_omega_rpm"][0] > 60.0, u.advice
    # Each way out applied in the twin's own string from its cycle at 60 rpm, at eight phases:
    # where it does not end the stick-slip, the advice says what it rests on that the surface
    # leaves to the prior (here m2's g: the cycle at one speed does not tell how the torque
    # falls with speed).
    chain, p_nm = one_dof(), np.array(M2_NM)
    states = [state for _, state in cycles_at(chain, "m2", p_nm, 60.0 * RPM, 1.0)]
    left = {}
    for u in updates:
        rpm = u.advice["escape_omega_rpm"][0]
        if rpm not in left:
            left[rpm] = max(after_change(chain, "m2", p_nm, rpm * RPM, 1.0, state) for state in states)
        assert left[rpm] == 0.0 or "m2's g to the prior" in u.advice["words"], (rpm, left[rpm], u.advice["words"])
    # The way out along the posterior's spread of g, every string there ended, gets the twin's
    # bit out at every phase (measured: 140 and 165 rpm, 73 kN, where the drawn strings' 80 rpm
    # and 159-183 kN leave it stuck 41-47 % of the time).
    for u in updates:
        spread = u.advice["spread"]
        assert spread["open"] == ["m2's g"], u.advice
        for rpm, ratio in ((spread["speed_rpm"], 1.0), (60.0, spread["wob_kn"] / 244.2)):
            stuck = max(after_change(chain, "m2", p_nm, rpm * RPM, ratio, state) for state in states)
            assert stuck == 0.0, (rpm, ratio, stuck, u.advice["words"])
    lines = [
        json.loads(line)
        for line in run_cli(
            cli, "watch", str(path), "--json", "--laws", "m2,m3", "--window-s", "150", "--step-s", "150",
            "--backend", "cpu", "--seed", "4",
        ).stdout.splitlines()
    ]
    for ours, theirs in zip(updates, lines, strict=True):
        for key in ("laws", "advice", "check", "epsilon"):
            assert ours.document[key] == theirs[key], key
