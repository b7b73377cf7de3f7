"""The model evidence from Python: the command line's numbers bit for bit, its tables as
DataFrames, posterior sets as pyABC's, and bad arguments refused by name."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import bitrock
from conftest import DEMO_CSV, REPO, run_cli

# The check by re-simulation has tests of its own; the others go without it.
SMALL = {"laws": ["m2", "m3"], "particles": 60, "islands": 3, "seed": 5, "backend": "cpu", "check": 0}


@pytest.fixture(scope="module")
def small(demo: bitrock.Record) -> bitrock.Evidence:
    return bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **SMALL)


def test_python_and_the_command_line_give_the_same_evidence(cli, small) -> None:
    done = run_cli(
        cli, "evidence", str(DEMO_CSV), "--thin", "4", "--laws", "m2,m3", "--particles", "60", "--islands", "3",
        "--seed", "5", "--backend", "cpu", "--check", "0", "--json",
    )
    document = json.loads(done.stdout)
    for a, b in zip(document["laws"], small.document["laws"]):
        assert a["law"] == b["law"]
        assert a["ln_z"] == b["ln_z"] and a["island_ln_z"] == b["island_ln_z"]
        assert a["probability"] == b["probability"]
    assert document["separations"] == small.document["separations"]
    assert document["bayes_factors"] == small.document["bayes_factors"]
    assert document["warnings"] == small.document["warnings"]


def test_every_evidence_setting_is_a_keyword_and_a_flag(cli) -> None:
    """The evidence's settings pass one gate in the library: each of its fields is a keyword of
    ``bitrock.evidence`` and a flag of ``bitrock evidence``, so that none exists on one
    surface alone."""
    fields = bitrock._bitrock.settings_fields("evidence")
    assert {"particles", "ess_share", "max_sweeps", "start_from", "noise"} <= set(fields)
    keywords = inspect.signature(bitrock.evidence).parameters
    flags = run_cli(cli, "evidence", "--help").stdout
    assert [f for f in fields if f not in keywords] == []
    assert [f for f in fields if f"--{f.replace('_', '-')}" not in flags] == []


def test_the_sampler_s_step_settings_give_the_command_s_evidence(cli) -> None:
    settings = {**SMALL, "ess_share": 0.7, "max_sweeps": 5, "max_stages": 300}
    mine = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **settings)
    done = run_cli(
        cli, "evidence", str(DEMO_CSV), "--thin", "4", "--laws", "m2,m3", "--particles", "60", "--islands", "3",
        "--seed", "5", "--backend", "cpu", "--ess-share", "0.7", "--max-sweeps", "5", "--max-stages", "300", "--json",
    )
    document = json.loads(done.stdout)
    assert [law["ln_z"] for law in document["laws"]] == [law["ln_z"] for law in mine.document["laws"]]
    # The settings reach the sampler: the default steps give another estimate.
    default = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **SMALL)
    assert [law["ln_z"] for law in default.document["laws"]] != [law["ln_z"] for law in mine.document["laws"]]


def test_the_evidence_warns_what_its_document_warns() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ev = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **SMALL)
    said = [str(w.message) for w in caught if issubclass(w.category, bitrock.BitrockWarning)]
    # m3's posterior runs to the end of a box on this short run: said, and kept in the document.
    assert any("the posterior of m3 reaches the end of its box" in m for m in ev.warnings), ev.warnings
    for message in ev.warnings:
        assert message in said
    assert [w["kind"] for w in ev.document["warnings"]] == ["cut_by_box"] * len(ev.warnings)


def test_the_samplers_start_from_the_boxes_the_fits_or_both_as_on_the_command_line(cli) -> None:
    record = bitrock.read_record(DEMO_CSV, thin=4)
    # One model of the residuals, so that each start's evidence is of the same one; no
    # refinement, which runs again only a start the law keeps (the box alone is always kept).
    model = {"noise": "iid", "scale_by_wob": True, "refine_rounds": 0}
    from_fits = bitrock.evidence(record, **SMALL, **model, start_from="fit")
    from_boxes = bitrock.evidence(record, **SMALL, **model, start_from="box")
    from_both = bitrock.evidence(record, **SMALL, **model)
    done = run_cli(
        cli, "evidence", str(DEMO_CSV), "--thin", "4", "--laws", "m2,m3", "--particles", "60", "--islands", "3",
        "--seed", "5", "--backend", "cpu", "--noise", "iid", "--scale-by-wob", "--refine-rounds", "0", "--json",
    )
    document = json.loads(done.stdout)
    assert from_fits.document["sampler"]["start"] == "fit"
    assert from_boxes.document["sampler"]["start"] == "box"
    assert document["sampler"]["start"] == from_both.document["sampler"]["start"] == "both"
    assert [law["island_ln_z"] for law in document["laws"]] == [law["island_ln_z"] for law in from_both.document["laws"]]
    # From the boxes the tempered path is longer: more steps, more candidates.
    for fit, box in zip(from_fits.document["laws"], from_boxes.document["laws"]):
        assert sum(fit["stages"]) < sum(box["stages"]) and fit["candidates_scored"] < box["candidates_scored"]
    # From both, the box's islands are the box's alone (the same random streams), and the
    # law's ln Z is one start's or both weighed, as each start's row says.
    starts = from_both.starts
    assert sorted(starts["law"].unique()) == ["m2", "m3"] and len(starts) == 4
    assert from_boxes.starts.empty
    for law, box in zip(from_both.laws, from_boxes.document["laws"]):
        rows = starts[starts["law"] == law].set_index("start")
        assert rows.loc["box", "ln_z"] == box["ln_z"]
        assert rows["kept"].any()
        if not rows["kept"].all():
            kept = rows[rows["kept"]].iloc[0]
            assert from_both.table.loc[law, "ln_z"] == kept["ln_z"]
            assert kept["ln_z"] > rows[~rows["kept"]].iloc[0]["ln_z"]


def test_an_evidence_directory_reads_back_and_maps_as_the_evidence_in_memory(cli, tmp_path) -> None:
    record = bitrock.read_record(DEMO_CSV, thin=4)
    kept = bitrock.evidence(record, **SMALL, out=tmp_path / "ev")
    read = bitrock.read_evidence(tmp_path / "ev")
    assert read.document == json.loads(json.dumps(kept.document))
    assert read.table.equals(kept.table)
    # The record travels with the evidence, in memory and in its directory.
    for evidence in (kept, read):
        np.testing.assert_array_equal(evidence.record.calibration()[1], record.calibration()[1])
    assert read.summary().equals(kept.summary())
    axes = {"omega_rpm": "40:160:4", "wob_kn": "100:300:3", "samples": 40, "backend": "cpu"}
    from_dir = bitrock.stability(tmp_path / "ev", **axes)
    from_memory = bitrock.stability(kept, **axes)
    np.testing.assert_array_equal(from_dir["probability_unstable"], from_memory["probability_unstable"])
    # The command's --run maps the same directory alike.
    done = run_cli(cli, "stability", "--run", str(tmp_path / "ev"), "--json", "--omega-rpm", "40:160:4",
                   "--wob-kn", "100:300:3", "--samples", "40", "--backend", "cpu")
    grids = json.loads(done.stdout)["probability_unstable"]
    for law in ("m2", "m3"):
        np.testing.assert_array_equal(np.array(grids[law]), from_dir["probability_unstable"].sel(law=law).values)
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.evidence(record, **SMALL, out=tmp_path / "ev")
    assert caught.value.argument == "out"
    bitrock.evidence(record, **{**SMALL, "seed": 6}, out=tmp_path / "ev", force=True)
    assert bitrock.read_evidence(tmp_path / "ev").document["sampler"]["seed"] == 6


def test_an_evidence_in_memory_saves_as_the_directory_out_writes(small, tmp_path) -> None:
    assert small.path is None
    saved = small.save(tmp_path / "saved")
    written = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **SMALL, out=tmp_path / "out")
    assert saved.path == str(tmp_path / "saved") and written.path == str(tmp_path / "out")

    def timeless(value):
        """``value`` without its clock readings (``seconds``), which differ between two runs."""
        if isinstance(value, dict):
            return {k: timeless(v) for k, v in value.items() if k != "seconds"}
        if isinstance(value, list):
            return [timeless(v) for v in value]
        return value

    assert saved.document == json.loads(json.dumps(small.document))
    assert timeless(saved.document) == timeless(written.document)
    for name in ("posterior.csv", "data.csv", "record.json", "job.json"):
        assert (tmp_path / "saved" / name).read_bytes() == (tmp_path / "out" / name).read_bytes(), name
    # A stored evidence is saved already; a directory that holds one is replaced only by force.
    with pytest.raises(bitrock.InputError, match="stored already") as caught:
        saved.save(tmp_path / "again")
    assert caught.value.argument == "path"
    with pytest.raises(bitrock.InputError, match="holds an evidence") as caught:
        small.save(tmp_path / "saved")
    assert caught.value.argument == "path"
    small.save(tmp_path / "saved", force=True)
    # An evidence in memory pickles whole (to a worker and back, say) and saves alike.
    import pickle

    copy = pickle.loads(pickle.dumps(small))
    assert copy.document == small.document and copy.path is None
    copy.save(tmp_path / "pickled")
    for name in ("evidence.json", "posterior.csv", "data.csv", "record.json", "job.json"):
        assert (tmp_path / "pickled" / name).read_bytes() == (tmp_path / "saved" / name).read_bytes(), name


def test_the_evidence_s_islands_are_the_chains_arviz_reads(small) -> None:
    import arviz as az

    tree = small.to_datatree()
    root = tree.to_dataset()
    assert list(root["law"].values) == ["m2", "m3"]
    np.testing.assert_array_equal(root["ln_z"].values, small.table["ln_z"].to_numpy())
    for entry in small.document["laws"]:
        law = entry["law"]
        node = tree[law]
        posterior = node["posterior"].to_dataset()
        assert list(posterior.data_vars) == entry["names"]
        assert posterior[entry["names"][0]].attrs["units"] == entry["units"][0]
        # One chain per island the law kept (of one start, or of both where they agree), each
        # island's ln Z beside it.
        island = np.asarray(entry["posterior"]["island"])
        chains = len(entry["island_ln_z"])
        assert posterior.sizes["chain"] == chains and chains in (SMALL["islands"], 2 * SMALL["islands"])
        np.testing.assert_array_equal(node["sample_stats"].to_dataset()["island_ln_z"].values, entry["island_ln_z"])
        frame, weights = small.posterior(law)
        count = max(np.bincount(island))
        assert posterior.sizes["draw"] == count
        name = entry["names"][0]
        for chain in range(chains):
            own = island == chain
            w = weights[own] / weights[own].sum()
            values, drawn = np.unique(posterior[name].values[chain], return_counts=True)
            # Systematic resampling within the island: each set ⌊N·w⌋ or ⌈N·w⌉ times (sets
            # of one value, which a sampler's resampling leaves, between the sums of those).
            for value, n in zip(values, drawn):
                shares = count * w[frame[name].to_numpy()[own] == value]
                assert np.floor(shares).sum() - 1e-9 <= n <= np.ceil(shares).sum() + 1e-9
        major = int(az.__version__.split(".")[0])
        data = node if major >= 1 else az.InferenceData.from_datatree(node)
        summary = az.summary(data, kind="diagnostics")
        assert list(summary.index) == entry["names"]
        assert np.isfinite(summary["r_hat"]).all()
    # m2's islands agree on this record: R-hat near 1.
    m2 = tree["m2"]
    data = m2 if int(az.__version__.split(".")[0]) >= 1 else az.InferenceData.from_datatree(m2)
    assert (az.summary(data, kind="diagnostics")["r_hat"] < 1.05).all()
    assert small.to_datatree(draws=25)["m3"]["posterior"].to_dataset().sizes["draw"] == 25
    with pytest.raises(bitrock.InputError) as caught:
        small.to_datatree(draws=0)
    assert caught.value.argument == "draws"


def test_the_evidence_reads_as_tables_and_posterior_sets(small) -> None:
    table = small.table
    assert list(table.index) == ["m2", "m3"]
    assert table["probability"].sum() == pytest.approx(1.0, abs=1e-12)
    assert (table["ln_z_error"] > 0).all()
    assert table["residual_lag1"].between(-1, 1).all()
    ln_b, error = small.bayes_factor("m3", "m2")
    assert ln_b == table.loc["m3", "ln_z"] - table.loc["m2", "ln_z"]
    assert error == pytest.approx(np.hypot(table.loc["m3", "ln_z_error"], table.loc["m2", "ln_z_error"]))
    # P(m3)/P(m2) = e^{ln B} with equal prior weights.
    assert np.log(table.loc["m3", "probability"] / table.loc["m2", "probability"]) == pytest.approx(ln_b, abs=1e-6)
    # The split: the favoured law's ln B = the data's part + the boxes' part, each law's Occam
    # factor its ln Z less its ⟨ln L⟩.
    (factor,) = small.bayes_factors.itertuples()
    favoured, against = factor.favoured, factor.against
    assert factor.ln_b == table.loc[favoured, "ln_z"] - table.loc[against, "ln_z"] >= 0
    laws = {law["law"]: law for law in small.document["laws"]}
    assert factor.data_nats == laws[favoured]["mean_ln_l"] - laws[against]["mean_ln_l"]
    assert factor.data_nats + factor.boxes_nats == pytest.approx(factor.ln_b, abs=1e-9)
    assert factor.strength in {"undecided", "decided_by_the_boxes", "positive", "strong", "very_strong"}
    for law in laws.values():
        assert law["ln_z"] - law["mean_ln_l"] == pytest.approx(law["occam_nats"], abs=1e-9)
    params, weights = small.posterior("m2")
    assert list(params.columns) == ["tsb", "tcb", "g"]
    # Every particle of every island m2 kept (both starts here, which agree), none refined.
    assert laws["m2"]["refinements"] == 0
    assert len(params) == len(weights) == 60 * len(laws["m2"]["island_ln_z"])
    assert weights.sum() == pytest.approx(1.0, abs=1e-12)
    # kN·m, the record's unit: the static torque of the demo record is of order 10 kN·m.
    assert 1.0 < float(np.average(params["tsb"], weights=weights)) < 100.0
    separations = small.separations
    assert len(separations) == 2 and set(separations["truth"]) == {"m2", "m3"}
    assert "most probable" in repr(small)
    # One answer: the pair's Bayes factor, its word and numbers, as the command prints it last.
    answer = small.answer
    assert answer["method"] == "evidence"
    assert (answer["law"], answer["runner_up"]) == (favoured, against)
    assert (answer["ln_b"], answer["strength"]) == (factor.ln_b, factor.strength)
    assert answer["probability"] == table.loc[favoured, "probability"]
    assert f"({factor.strength.replace('_', ' ')})>" in repr(small)


@pytest.mark.parametrize(
    ("arguments", "named"),
    [
        ({"islands": 1}, "islands"),
        ({"boxes": "wide"}, "boxes"),
        ({"prior_scale": -1.0}, "prior_scale"),
        ({"particles": "many"}, "particles"),
        ({"check": -1}, "check"),
        ({"start_from": "prior"}, "start_from"),
        ({"ess_share": 1.5}, "ess_share"),
        ({"max_sweeps": True}, "max_sweeps"),
        ({"noise": 2}, "noise"),
    ],
)
def test_bad_arguments_are_refused_by_name(demo, arguments, named) -> None:
    with pytest.raises(bitrock.InputError, match=named):
        bitrock.evidence(demo, **{**SMALL, **arguments})


def test_an_unknown_law_is_refused(small) -> None:
    with pytest.raises(bitrock.InputError, match="m4"):
        small.posterior("m4")


def test_the_check_by_resimulation_is_the_command_lines(cli) -> None:
    checked = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), **{**SMALL, "check": 2})
    done = run_cli(
        cli, "evidence", str(DEMO_CSV), "--thin", "4", "--laws", "m2,m3", "--particles", "60", "--islands", "3",
        "--seed", "5", "--backend", "cpu", "--check", "2", "--json", "--quiet",
    )
    document = json.loads(done.stdout)["check"]
    assert document["rows"] == checked.document["check"]["rows"]
    assert json.loads(done.stdout)["answer"] == checked.answer
    table = checked.check
    assert list(table.index) == ["m2", "m3"]
    shares = table[["decided_right", "undecided", "decided_wrong"]].sum(axis=1)
    assert np.allclose(shares, 1.0)
    assert np.allclose(table[["p_m2", "p_m3"]].sum(axis=1), 1.0)
    for law in ("m2", "m3"):
        assert table.loc[law, "p_m2"] == document["rows"][["m2", "m3"].index(law)]["mean_probability"][0]


def test_the_check_runs_by_default_and_check_0_turns_it_off(small) -> None:
    default = {key: value for key, value in SMALL.items() if key != "check"}
    checked = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=8), **default)
    document = checked.document["check"]
    assert document["replicates"] == 4
    assert document["sampler"] == {"particles": 60, "islands": 2, "start": "fit"}
    assert list(checked.check.index) == ["m2", "m3"]
    assert checked.answer["check"]["replicates"] == 4
    assert "the check decided" in checked.answer["sentence"]
    assert small.check is None and "check" not in small.answer


def test_the_evidence_posterior_maps_with_its_law_probabilities(small) -> None:
    maps = bitrock.stability(small, omega_rpm="20:220:11", wob_kn="20:700:9", samples=40, backend="cpu")
    probabilities = small.probabilities
    for law in maps["law"].values:
        assert float(maps["probability"].sel(law=law)) == pytest.approx(probabilities[law], abs=1e-9)
    grid = maps["probability_unstable"].values
    assert np.all(np.isnan(grid) | ((grid >= 0) & (grid <= 1)))
    assert set(maps["law"].values) == {law for law, p in probabilities.items() if p > 0}


def test_the_noise_model_is_compared_or_named(small) -> None:
    models = small.noise_models
    # Each noise model with the torque as the laws give it, then scaled by the record's weight
    # on bit.
    assert list(models["model"]) == ["iid", "ar1", "iid", "ar1"]
    assert models["w_ref_kn"].isna().sum() == 2
    assert models["probability"].sum() == pytest.approx(1.0, abs=1e-12)
    best = models.loc[models["probability"].idxmax()]
    assert small.noise_model == best["model"]
    assert small.w_ref_kn == (None if np.isnan(best["w_ref_kn"]) else pytest.approx(best["w_ref_kn"]))
    named = bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), noise="ar1", **SMALL)
    assert named.noise_model == "ar1" and list(named.noise_models["model"]) == ["ar1", "ar1"]
    with pytest.raises(bitrock.InputError, match="noise"):
        bitrock.evidence(bitrock.read_record(DEMO_CSV, thin=4), noise="ar2", **SMALL)


def test_a_record_with_weight_on_bit_compares_the_torque_scaled_by_it() -> None:
    # Torque follows a weight on bit that fluctuates by 12 kN with a 5 s correlation time.
    frame = bitrock.simulate(
        "m2", omega_rpm=60, duration_s=120, sample_hz=10, noise_torque_knm=0.6, wob_fluctuation_kn=12,
        wob_correlation_s=5, seed=3,
    )
    record = bitrock.read_record(frame)
    ev = bitrock.evidence(record, laws=["m2", "m4"], particles=60, islands=2, seed=5, backend="cpu", check=0)
    # m4's prior is its box cut to the cubics within twice the record's largest torque: the
    # share of the box it keeps is the box's shape's, on any record; m2's is its box.
    assert ev.table.loc["m2", "prior_share"] == 1.0
    assert abs(np.log(ev.table.loc["m4", "prior_share"]) + 2.412) < 0.03
    models = ev.noise_models
    assert len(models) == 4 and models["w_ref_kn"].notna().sum() == 2
    # W_ref is the calibration samples' mean weight on bit, near the record's.
    assert models["w_ref_kn"].dropna().iloc[0] == pytest.approx(float(frame["wob_kn"].mean()), rel=0.02)
    # The data choose the scaled torque, by tens of nats.
    scaled = models[models["w_ref_kn"].notna()]["ln_evidence"].max()
    plain = models[models["w_ref_kn"].isna()]["ln_evidence"].max()
    assert scaled - plain > 10.0
    assert ev.w_ref_kn == pytest.approx(models["w_ref_kn"].dropna().iloc[0])
    # Its posterior maps at its own W_ref, not the paper's 244.2 kN.
    grid = {"omega_rpm": "20:220:6", "wob_kn": "50:600:6", "samples": 20, "backend": "cpu"}
    maps = bitrock.stability(ev, **grid)
    assert maps.equals(bitrock.stability(ev, w_ref_kn=ev.w_ref_kn, **grid))
    assert not maps.equals(bitrock.stability(ev, w_ref_kn=244.2, **grid))


def test_check_selection_of_an_evidence_directory_is_the_evidence_s_own_check(tmp_path) -> None:
    record = bitrock.read_record(DEMO_CSV, thin=4)
    checked = bitrock.evidence(record, **{**SMALL, "check": 2})
    bitrock.evidence(record, **SMALL, out=tmp_path / "ev")
    matrix = bitrock.check_selection(tmp_path / "ev", replicates=2, progress=False)
    # The same replicates as the evidence's own check, written into the directory.
    document = matrix.attrs["document"]
    assert document["rows"] == checked.document["check"]["rows"]
    # The answer the check weighs, written beside it.
    assert bitrock.read_evidence(tmp_path / "ev").answer == checked.answer
    assert bitrock.read_evidence(tmp_path / "ev").document["check"] == document
    assert list(matrix.index) == ["m2", "m3"] and list(matrix.columns) == ["m2", "m3"]
    np.testing.assert_allclose(matrix.sum(axis=1), 1.0, atol=1e-12)
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.check_selection(tmp_path / "ev", replicates=2, batch=2, progress=False)
    assert caught.value.argument == "batch"


def _without_seconds(value):
    if isinstance(value, dict):
        return {k: _without_seconds(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_without_seconds(v) for v in value]
    return value


def test_an_evidence_stopped_by_ctrl_c_is_resumed_to_the_uninterrupted_one(tmp_path) -> None:
    import os
    import signal
    import threading

    import time

    record = bitrock.read_record(DEMO_CSV, thin=4)
    settings = {"laws": ["m2", "m3"], "particles": 200, "islands": 2, "seed": 2, "backend": "cpu"}
    started = time.monotonic()
    whole = bitrock.evidence(record, **settings, out=tmp_path / "whole")
    # The evidence's own time, without its check's.
    took = time.monotonic() - started - whole.document["check"]["seconds"]
    assert not (tmp_path / "whole" / "unfinished").exists()
    # Ctrl-C a third of the way into the evidence: the evidence stops, kept under way in its directory. Taken
    # as an interactive session takes it: a test runner started in the background inherits
    # SIGINT ignored.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer = threading.Timer(took / 3, os.kill, (os.getpid(), signal.SIGINT))
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            bitrock.evidence(record, **settings, out=tmp_path / "ev")
        timer.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert (tmp_path / "ev" / "unfinished" / "job.json").is_file()
    with pytest.raises(bitrock.InputError, match="resume_evidence") as caught:
        bitrock.evidence(record, **settings, out=tmp_path / "ev")
    assert caught.value.argument == "out"
    # Checked by default, as the uninterrupted evidence was, to the same check.
    resumed = bitrock.resume_evidence(tmp_path / "ev")
    assert resumed.check is not None
    assert _without_seconds(resumed.document) == _without_seconds(whole.document)
    assert _without_seconds(bitrock.read_evidence(tmp_path / "ev").document) == _without_seconds(resumed.document)
    with pytest.raises(bitrock.InputError, match="finished evidence") as caught:
        bitrock.resume_evidence(tmp_path / "ev")
    assert caught.value.argument == "directory"


def test_the_evidence_is_nested_sampling_s_within_the_errors(tmp_path) -> None:
    """An independent reference: dynesty's nested sampling of the same likelihood over the same
    boxes (``benches/evidence_nested.py``, which checks first that its data, scaling and torque
    give bitrock's ρ at every law's least-squares estimate), on a short, noisy record of m2
    whose laws the data do not all separate, so that the probabilities are not all 0 or 1.
    Eight islands per start, so that the errors the comparison is judged by are not themselves
    rough (from four, m3's fit start here came out 0.27 nats above an importance-sampling
    reference of two million draws, −573.00 ± 0.01, with an error of 0.09)."""
    frame = bitrock.simulate("m2", omega_rpm=60, duration_s=40, sample_hz=5, noise_torque_knm=1.5, seed=3)
    out = tmp_path / "evidence"
    ev = bitrock.evidence(bitrock.read_record(frame), noise="iid", islands=8, backend="cpu", seed=2, check=0, out=out)
    result = tmp_path / "nested.json"
    done = subprocess.run(
        [sys.executable, str(REPO / "benches" / "evidence_nested.py"), str(out), "--nlive", "400", "--seed", "1",
         "--out", str(result)],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    nested = {row["law"]: row for row in json.loads(result.read_text())["laws"]}
    assert sorted(nested) == sorted(ev.laws)
    # ln Z within 3 joint errors of the two estimates.
    for law, row in nested.items():
        assert abs(row["difference_in_joint_errors"]) <= 3.0, row
    # P(m | y) under equal prior law probabilities, from nested sampling's ln Z: within 0.05.
    ln_z = np.array([nested[law]["dynesty_ln_z"] for law in ev.laws])
    reference = np.exp(ln_z - ln_z.max()) / np.exp(ln_z - ln_z.max()).sum()
    probabilities = ev.table.loc[ev.laws, "probability"].to_numpy()
    assert np.abs(probabilities - reference).max() <= 0.05, (probabilities, reference)
    # Not a record on which every law but one is ruled out.
    assert np.sort(reference)[-2] > 0.01, reference


def test_the_evidence_summary_is_its_posterior_sets_weighted(small) -> None:
    """``Evidence.summary()`` reads as ``Result.summary()``: per law and parameter, the weighted
    moments and quantiles of the law's posterior sets, and whether the record narrowed its box."""
    table = small.summary()
    assert list(table.columns) == ["law", "parameter", "unit", "probability", "mean", "std_dev", "q01", "q50", "q99", "identified"]
    for law in small.laws:
        frame, weights = small.posterior(law)
        rows = table[table["law"] == law].set_index("parameter")
        assert list(rows.index) == list(frame.columns)
        w = weights / weights.sum()
        for name in frame.columns:
            values = frame[name].to_numpy()
            assert rows.loc[name, "mean"] == pytest.approx(float(np.sum(w * values)), rel=1e-12)
            assert rows.loc[name, "q01"] <= rows.loc[name, "q50"] <= rows.loc[name, "q99"]
            # The weighted median: at least half the weight on each side.
            assert w[values <= rows.loc[name, "q50"]].sum() >= 0.5 - 1e-12
            assert w[values >= rows.loc[name, "q50"]].sum() >= 0.5 - 1e-12
    # bitrock.plot.fit draws an evidence over its own record.
    pytest.importorskip("matplotlib")
    ax = bitrock.plot.fit(small)
    assert any(c.get_gid() == "record" for c in ax.collections)


def test_islands_apart_are_refined_as_on_the_command_line(cli) -> None:
    """Islands of a start the law keeps that end more than a nat apart are run again with twice
    the particles, ``refine_rounds`` times at most, as ``--refine-rounds`` says; what is still
    apart is ln Z's error, and P(m | y) carries its standard error."""
    record = bitrock.read_record(DEMO_CSV, thin=4)
    refined = bitrock.evidence(record, **SMALL)
    plain = bitrock.evidence(record, **SMALL, refine_rounds=0)
    table, plain_table = refined.table, plain.table
    assert (plain_table["refinements"] == 0).all()
    assert (table["refinements"] <= 2).all()
    # Each start's islands still apart carry half their range as their error.
    for _, row in refined.starts.iterrows():
        if row["island_spread"] > 1.0:
            assert row["ln_z_error"] >= row["island_spread"] / 2
    for law in refined.document["laws"]:
        assert 0.0 <= law["probability_error"] <= 0.5
    done = run_cli(
        cli, "evidence", str(DEMO_CSV), "--thin", "4", "--laws", "m2,m3", "--particles", "60", "--islands", "3",
        "--seed", "5", "--backend", "cpu", "--refine-rounds", "0", "--json",
    )
    document = json.loads(done.stdout)
    assert [law["ln_z"] for law in document["laws"]] == [law["ln_z"] for law in plain.document["laws"]]
    assert [law["refinements"] for law in document["laws"]] == [0, 0]
    with pytest.raises(bitrock.InputError, match="refine_rounds"):
        bitrock.evidence(record, **SMALL, refine_rounds=7)
