"""ABC runs from Python: tables, distributions, the DataTree, reproducibility, run directories,
refusals and interruption."""

from __future__ import annotations

import html
import os
import pickle
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import numpy as np
import pandas as pd
import pandas as pd
import pytest

import bitrock


def test_population_and_probability_tables(small_run: bitrock.Result) -> None:
    populations = small_run.populations
    assert list(populations.columns) == ["epsilon", "accepted", "drawn", "acceptance_rate", "ess", "thin", "seconds"]
    assert (populations["accepted"] == 300).all()
    # A rejection run's weights are equal: ESS = N, never thin.
    assert (populations["ess"] == 300).all() and not populations["thin"].any()
    assert np.isinf(populations["epsilon"].iloc[0])
    assert (np.diff(populations["epsilon"].to_numpy()[1:]) < 0).all()
    probabilities = small_run.model_probabilities
    assert list(probabilities.columns) == ["m1", "m2", "m3", "m4", "epsilon"]
    assert len(probabilities) == len(populations)
    np.testing.assert_allclose(probabilities[["m1", "m2", "m3", "m4"]].sum(axis=1), 1.0, rtol=0, atol=1e-12)


def test_the_paper_s_abc_answers_with_its_label_and_says_what_its_tolerance_makes_of_it(demo: bitrock.Record) -> None:
    with pytest.warns(bitrock.BitrockWarning, match=r"likelihood scales above the best fit") as caught:
        run = bitrock.abc(demo, particles=300, seed=11, backend="cpu", progress=False)
    assert [str(w.message) for w in caught] == run.document["warnings"]
    assert caught[0].filename == __file__
    answer = run.answer
    assert answer is not None and answer["method"] == "paper_abc"
    # At ε = 0.014, far above the demo record's likelihood scale, the priors decide.
    assert answer["strength"] == "decided_by_the_boxes"
    last = run.model_probabilities.iloc[-1].drop("epsilon").sort_values(ascending=False)
    assert (answer["law"], answer["runner_up"]) == (last.index[0], last.index[1])
    assert answer["ln_b"] == pytest.approx(np.log(last.iloc[0] / last.iloc[1]), abs=1e-12)
    for frame in (run.model_probabilities, run.summary()):
        assert frame.attrs["label"] == "the paper's ABC, P(m | ρ < ε)"
    assert "P(m | ρ < ε)" in repr(run) and "(decided by the boxes)" in repr(run)
    assert answer["sentence"] in html.unescape(run._repr_html_())


def test_get_distribution_as_pyabc_returns_it(small_run: bitrock.Result) -> None:
    total = 0
    for law, k in [("m1", 4), ("m2", 3), ("m3", 6), ("m4", 4)]:
        frame, weights = small_run.get_distribution(law)
        assert frame.shape == (len(weights), k)
        assert frame.columns.name == "name"
        if len(weights):
            assert weights.sum() == pytest.approx(1.0, abs=1e-12)
        total += len(weights)
    assert total == 300
    first, _ = small_run.get_distribution("m2", population=0)
    assert not first.equals(small_run.get_distribution("m2")[0])
    with pytest.raises(bitrock.InputError):
        small_run.get_distribution("m7")
    with pytest.raises(bitrock.InputError):
        small_run.get_distribution("m2", population=99)


def test_the_particles_lie_in_their_prior_and_match_the_probabilities(small_run: bitrock.Result) -> None:
    document = small_run.document
    last = small_run.particles()
    for prior in document["priors"]:
        names, params, _w, rho, _i = last[prior["law"]]
        low, high = np.array(prior["lower"]), np.array(prior["upper"])
        assert ((params >= low - 1e-9 * abs(low)) & (params <= high + 1e-9 * abs(high))).all(), prior["law"]
        assert (rho <= small_run.populations["epsilon"].iloc[-1]).all()
    probabilities = small_run.model_probabilities.iloc[-1]
    for law, (_n, params, _w, _r, _i) in last.items():
        assert probabilities[law] == pytest.approx(len(params) / 300, abs=1e-12)


def test_summary_lists_every_parameter(small_run: bitrock.Result) -> None:
    summary = small_run.summary()
    assert len(summary) == 17
    assert (summary["q01"] <= summary["q50"]).all() and (summary["q50"] <= summary["q99"]).all()


def test_to_datatree_has_the_groups_arviz_reads(small_run: bitrock.Result) -> None:
    tree = small_run.to_datatree()
    assert set(tree.children) == {"m1", "m2", "m3", "m4"}
    m2 = tree["m2"]
    posterior = m2["posterior"].to_dataset()
    assert set(posterior.data_vars) == {"tsb", "tcb", "g"}
    frame, weights = small_run.get_distribution("m2")
    assert posterior.sizes["chain"] == 1 and posterior.sizes["draw"] == len(weights)
    assert np.array_equal(posterior["tsb"].values[0], frame["tsb"].to_numpy())
    assert posterior["tsb"].attrs["units"] == "kN·m"
    stats = m2["sample_stats"].to_dataset()
    assert stats["weight"].values.sum() == pytest.approx(1.0, abs=1e-12)
    root = tree.to_dataset()
    assert root["model_probabilities"].dims == ("population", "law")
    assert np.array_equal(root["model_probabilities"].values, small_run.model_probabilities[["m1", "m2", "m3", "m4"]].to_numpy())


def test_the_same_seed_gives_the_same_particles(demo: bitrock.Record, small_run: bitrock.Result) -> None:
    again = bitrock.abc(demo, particles=300, seed=11, backend="cpu", progress=False)
    other = bitrock.abc(demo, particles=300, seed=12, backend="cpu", progress=False)
    for law, (_n, params, weights, rho, index) in small_run.particles().items():
        _n2, params2, weights2, rho2, index2 = again.particles()[law]
        assert np.array_equal(params, params2) and np.array_equal(weights, weights2)
        assert np.array_equal(rho, rho2) and np.array_equal(index, index2)
    assert not np.array_equal(small_run.particles()["m2"][1], other.particles().get("m2", (0, np.zeros(0)))[1])


def test_smc_with_a_schedule(demo: bitrock.Record) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = bitrock.abc(demo, particles=300, sampler="smc", epsilons=[0.05, 0.03, 0.02], seed=3, backend="cpu", progress=False)
    # A schedule ends the run: no note about a floor; the one warning is what ε = 0.02 makes of
    # the probabilities, as the command says it.
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith("ε = 0.02000 lies ") and "ratios of the laws' prior volumes" in said[0], said
    assert run.document["warnings"] == said
    assert list(run.populations["epsilon"])[1:] == [0.05, 0.03, 0.02]
    assert run.document["stop_reason"] == "schedule_exhausted"
    assert run.document["stop_description"] == "the `epsilons` schedule ran out"


def test_the_classic_smc_runs_by_name(demo: bitrock.Record) -> None:
    settings = {"particles": 300, "sampler": "smc", "seed": 4, "backend": "cpu", "max_populations": 3, "progress": False}
    classic = bitrock.abc(demo, refill="fresh", law_proposal="kernel", p_stay=0.6, perturbation="global", **settings)
    default = bitrock.abc(demo, **settings)
    sampler = classic.document["config"]["sampler"]
    assert (sampler["refill"], sampler["law_proposal"], sampler["p_stay"]) == ("fresh", "kernel", 0.6)
    assert sampler["perturbation"] == "global"
    chosen = default.document["config"]["sampler"]
    assert (chosen["refill"], chosen["law_proposal"], chosen["perturbation"]) == ("survivors", "worth", "local")
    # Population 0 is the rejection sampler's in both; later ones differ with the scheme.
    assert classic.populations["drawn"].iloc[0] == default.populations["drawn"].iloc[0]
    assert (classic.populations["drawn"].iloc[1:].to_numpy() != default.populations["drawn"].iloc[1:].to_numpy()).any()


def test_progress_goes_to_a_callable(demo: bitrock.Record) -> None:
    seen: list[tuple[int, int, int, int, float | None]] = []
    bitrock.abc(demo, particles=200, seed=2, backend="cpu", max_populations=3, progress=lambda *a: seen.append(a))
    populations = [s[0] for s in seen]
    assert populations == sorted(populations) and set(populations) == {0, 1, 2}
    assert all(0 <= accepted <= target == 200 for _g, accepted, target, _d, _e in seen)


def test_the_bars_leave_a_line_per_population(demo: bitrock.Record, capsys) -> None:
    pytest.importorskip("tqdm")
    run = bitrock.abc(demo, particles=200, seed=2, backend="cpu", max_populations=3, progress=True)
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("population")]
    table = run.populations
    assert len(lines) == 3
    for g, line in enumerate(lines):
        row = table.loc[g]
        eps = "∞" if np.isinf(row.epsilon) else f"{row.epsilon:.5g}"
        assert line == f"population {g} (ε {eps}): 200 particles of {row.drawn} drawn (acceptance {200 / row.drawn:.3g})"


@pytest.mark.parametrize(
    ("arguments", "argument", "words"),
    [
        ({"particles": 0}, "particles", "particles: must be at least 1"),
        ({"sampler": "gibbs"}, "sampler", "`gibbs` is not one of the accepted values"),
        ({"backend": "tpu"}, "backend", "`tpu` is not one of the accepted values"),
        ({"kernel_scale": 2.0}, "kernel_scale", "kernel_scale: applies only to `sampler` smc"),
        ({"refill": "fresh"}, "refill", "refill: applies only to `sampler` smc"),
        ({"sampler": "smc", "refill": "some"}, "refill", "`some` is not one of the accepted values"),
        ({"sampler": "smc", "p_stay": 0.5}, "p_stay", "p_stay: applies only to `law_proposal` kernel"),
        (
            {"sampler": "smc", "perturbation": "local", "kernel_scale": 1.0},
            "kernel_scale",
            "kernel_scale: applies only to `perturbation` global",
        ),
        ({"delta": -0.1}, "delta", "delta:"),
        ({"epsilons": [0.05, 0.08]}, "epsilons", "epsilons:"),
    ],
)
def test_refused_settings_name_their_argument(demo: bitrock.Record, arguments, argument: str, words: str) -> None:
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.abc(demo, progress=False, **{"particles": 50, "backend": "cpu", **arguments})
    assert caught.value.argument == argument
    assert words in str(caught.value)
    assert "--" not in str(caught.value)
    # Survives pickling back from a worker process.
    back = pickle.loads(pickle.dumps(caught.value))
    assert type(back) is bitrock.InputError and back.argument == argument and str(back) == str(caught.value)


@pytest.mark.parametrize(
    "arguments, argument",
    [
        ({"particles": -5}, "particles"),
        ({"particles": True}, "particles"),
        ({"particles": "2000"}, "particles"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**70}, "seed"),
        ({"max_populations": 1.5}, "max_populations"),
        ({"epsilons": "0.05"}, "epsilons"),
        ({"epsilons": [0.05, "0.01"]}, "epsilons"),
        ({"laws": 2}, "laws"),
        ({"laws": ["m2", 3]}, "laws"),
    ],
)
def test_numbers_of_the_wrong_kind_or_range_name_their_argument(demo: bitrock.Record, arguments, argument: str) -> None:
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.abc(demo, progress=False, **{"particles": 50, "backend": "cpu", **arguments})
    assert caught.value.argument == argument
    assert str(caught.value).startswith(f"{argument}: ")
    assert repr(arguments[argument]) in str(caught.value)


def test_every_run_setting_is_a_keyword() -> None:
    """A run's settings pass one gate in the library: each of its fields is a keyword of
    ``bitrock.abc`` (the command's flags are checked beside the command)."""
    import inspect

    fields = bitrock._bitrock.settings_fields("abc")
    assert {"sampler", "particles", "perturbation", "devices", "prior_file"} <= set(fields)
    keywords = inspect.signature(bitrock.abc).parameters
    assert [f for f in fields if f not in keywords] == []


def test_the_drill_string_is_a_keyword_wherever_it_maps_or_advises() -> None:
    import inspect

    string = ["structure", "inertia_kg_m2", "omega_n_rad_s", "damping_ratio", "fe_file", "dp_elements", "bha_elements", "alpha", "beta"]
    for function in (bitrock.abc, bitrock.evidence, bitrock.stability):
        keywords = inspect.signature(function).parameters
        assert [k for k in string if k not in keywords] == [], function.__name__


def test_a_run_keeps_its_drill_string_and_maps_on_it(demo: bitrock.Record, tmp_path) -> None:
    rig = {"inertia_kg_m2": 0.02, "omega_n_rad_s": 5.0, "damping_ratio": 0.1}
    run = bitrock.abc(demo, particles=300, seed=11, backend="cpu", progress=False, out=tmp_path / "run", **rig)
    assert run.document["config"]["string"] == {"structure": "1dof", "lumped": rig}
    # The map of the stored run is on its own string: c_b* = −2ξω_n·I = −0.02 N·m·s/rad, so
    # the boundary is the paper string's scaled by 0.02 / 162.9 (c_b* of the paper's string).
    own = bitrock.stability(run.path, omega_rpm=[60.0], wob_kn=[100.0], backend="cpu", samples=10)
    paper = bitrock.stability(run.path, omega_rpm=[60.0], wob_kn=[100.0], backend="cpu", samples=10, inertia_kg_m2=383.33, omega_n_rad_s=0.85, damping_ratio=0.25)
    ratio = own["map_wob_kn"].values / paper["map_wob_kn"].values
    np.testing.assert_allclose(ratio, 0.02 / (2 * 0.25 * 0.85 * 383.33), rtol=1e-9)
    # A run kept in memory maps on its own string too.
    in_memory = bitrock.abc(demo, particles=300, seed=11, backend="cpu", progress=False, **rig)
    kept = bitrock.stability(in_memory, omega_rpm=[60.0], wob_kn=[100.0], backend="cpu", samples=10)
    np.testing.assert_array_equal(kept["map_wob_kn"].values, own["map_wob_kn"].values)
    with pytest.raises(bitrock.InputError, match="damping_ratio"):
        bitrock.abc(demo, particles=300, backend="cpu", progress=False, damping_ratio=-1.0)


def test_a_named_value_is_read_in_any_case(demo: bitrock.Record) -> None:
    upper = bitrock.abc(demo, laws="m2", particles=50, sampler="Rejection", backend="CPU", progress=False, seed=3)
    lower = bitrock.abc(demo, laws="m2", particles=50, sampler="rejection", backend="cpu", progress=False, seed=3)
    untimed = [[{k: v for k, v in p.items() if k != "seconds"} for p in r.document["populations"]] for r in (upper, lower)]
    assert untimed[0] == untimed[1]


def test_one_law_or_one_tolerance_where_a_list_belongs_is_a_list_of_one(demo: bitrock.Record) -> None:
    one = bitrock.abc(demo, laws="m2", epsilons=0.05, particles=100, backend="cpu", progress=False)
    assert one.laws == ["m2"]
    assert [p["epsilon"] for p in one.document["populations"]] == [None, 0.05]
    listed = bitrock.abc(demo, laws=["m2"], epsilons=[0.05], particles=100, backend="cpu", progress=False)
    for a, b in zip(listed.document["populations"], one.document["populations"], strict=True):
        assert (a["epsilon"], a["accepted"], a["draws"]) == (b["epsilon"], b["accepted"], b["draws"])
    # The command's comma-separated list reads as its laws.
    assert bitrock.abc(demo, laws="m2, m3", epsilons=0.05, particles=100, backend="cpu", progress=False).laws == ["m2", "m3"]


@pytest.mark.parametrize("source", [pd.Series([1.0, 2.0]), "demo.csv", None])
def test_a_source_that_is_not_a_record_is_refused_naming_the_argument(source) -> None:
    for call in (lambda: bitrock.abc(source, progress=False), lambda: bitrock.fit(source)):
        with pytest.raises(bitrock.InputError) as caught:
            call()
        assert caught.value.argument == "record"
        assert "bitrock.read_record" in str(caught.value)
        assert type(source).__name__ in str(caught.value)


def test_a_run_another_process_is_writing_is_said_to_be_so(demo: bitrock.Record, tmp_path) -> None:
    out = tmp_path / "run"
    bitrock.abc(demo, particles=200, seed=1, backend="cpu", max_populations=1, out=out, progress=False)
    # As a run that has stored its store but not yet its summary, its lock held by another
    # process (flock -o: held by flock itself, freed when it is killed).
    (out / "run.json").unlink()
    (out / ".bitrock-lock").write_text("4242")
    holder = subprocess.Popen(["flock", "-o", str(out / ".bitrock-lock"), "sleep", "60"])
    try:
        deadline = time.monotonic() + 10
        while subprocess.run(["flock", "-n", str(out / ".bitrock-lock"), "true"]).returncode == 0:
            assert time.monotonic() < deadline, "flock never took the lock"
            time.sleep(0.01)
        with pytest.raises(bitrock.InputError, match=r"being written by another process \(PID 4242\)"):
            bitrock.open_run(out)
    finally:
        holder.kill()
        holder.wait()
    # flock's child holds the lock's open file for a moment after its fork (it closes it before
    # it runs sleep): on a busy machine the lock outlives flock itself. Wait until it is free.
    deadline = time.monotonic() + 10
    while subprocess.run(["flock", "-n", str(out / ".bitrock-lock"), "true"]).returncode != 0:
        assert time.monotonic() < deadline, "the lock was never freed"
        time.sleep(0.01)
    with pytest.raises(bitrock.InputError, match="stopped before it finished"):
        bitrock.open_run(out)


def test_errors_are_pure_python_classes() -> None:
    assert issubclass(bitrock.InputError, bitrock.BitrockError) and issubclass(bitrock.InputError, ValueError)
    assert issubclass(bitrock.GpuError, bitrock.BitrockError)
    error = pickle.loads(pickle.dumps(bitrock.GpuError("no adapter")))
    assert str(error) == "no adapter"


def test_a_run_directory_is_written_opened_and_resumed(demo: bitrock.Record, tmp_path) -> None:
    out = tmp_path / "run"
    written = bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=3, out=out, progress=False)
    assert written.path == out and (out / "run.json").is_file()
    opened = bitrock.open_run(out)
    assert len(opened.populations) == 3
    for g in range(3):
        for law, (_n, params, *_rest) in written.particles(g).items():
            assert np.array_equal(params, opened.particles(g)[law][1])
    with pytest.raises(bitrock.InputError, match="holds a bitrock run; pass `force` to replace it") as caught:
        bitrock.abc(demo, particles=300, seed=11, backend="cpu", out=out, progress=False)
    assert caught.value.argument == "out"
    bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=2, out=out, force=True, progress=False)
    with pytest.warns(bitrock.BitrockWarning, match=r"continuing .* after population 1 \(2 stored\)"):
        resumed = bitrock.resume(out, max_populations=3, progress=False)
    assert len(resumed.populations) == 3
    for law, (_n, params, *_rest) in written.particles().items():
        assert np.array_equal(params, resumed.particles()[law][1])


def test_a_callback_that_raises_stops_the_run_and_leaves_it_resumable(demo: bitrock.Record, tmp_path) -> None:
    whole = bitrock.abc(demo, particles=300, seed=5, backend="cpu", out=tmp_path / "whole", progress=False)

    def stop_in_population_2(population: int, *_rest) -> None:
        if population == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        bitrock.abc(demo, particles=300, seed=5, backend="cpu", out=tmp_path / "cut", progress=stop_in_population_2)
    with pytest.raises(bitrock.InputError, match="stopped before it finished.*bitrock.resume"):
        bitrock.open_run(tmp_path / "cut")
    with pytest.warns(bitrock.BitrockWarning):
        resumed = bitrock.resume(tmp_path / "cut", progress=False)
    assert len(resumed.populations) == len(whole.populations)
    for law, (_n, params, *_rest) in whole.particles().items():
        assert np.array_equal(params, resumed.particles()[law][1])


def test_a_callbacks_own_exception_comes_back_and_the_run_stays_resumable(demo: bitrock.Record, tmp_path) -> None:
    class Enough(Exception):
        pass

    def stop_in_population_1(population: int, *_rest) -> None:
        if population == 1:
            raise Enough("the user's own reason")

    with pytest.raises(Enough, match="the user's own reason"):
        bitrock.abc(demo, particles=200, seed=5, backend="cpu", out=tmp_path / "cut", progress=stop_in_population_1)
    with pytest.warns(bitrock.BitrockWarning):
        resumed = bitrock.resume(tmp_path / "cut", max_populations=3, progress=False)
    assert [p["index"] for p in resumed.document["populations"]] == [0, 1, 2]


def test_ctrl_c_raises_keyboard_interrupt_within_a_second(tmp_path) -> None:
    # The child takes Ctrl-C as an interactive session does: a test runner started in the
    # background (a non-interactive shell's `&`) passes SIGINT on ignored, and Python then
    # leaves it ignored.
    script = textwrap.dedent(
        f"""
        import signal, sys, bitrock
        signal.signal(signal.SIGINT, signal.default_int_handler)
        def started(*_a):
            print("started", flush=True)
        bitrock.abc(bitrock.read_record(), particles=200000, max_draws=10**9, seed=1, backend="cpu",
                    out={str(tmp_path / "big")!r}, progress=started)
        """
    )
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "started"
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    _out, err = child.communicate(timeout=60)
    waited = time.monotonic() - sent
    assert child.returncode != 0 and "KeyboardInterrupt" in err, err
    # Batches are short; the interrupt is seen after the one in progress.
    assert waited < 5.0, f"Ctrl-C took {waited:.1f} s"
    assert (tmp_path / "big" / "run.json").exists() or (tmp_path / "big").is_dir()


def test_arviz_reads_a_laws_node(small_run: bitrock.Result) -> None:
    import arviz as az

    node = small_run.to_datatree()["m2"]
    major = int(az.__version__.split(".")[0])
    # ArviZ 1.x takes the DataTree itself; 0.23 converts it.
    data = node if major >= 1 else az.InferenceData.from_datatree(node)
    summary = az.summary(data, kind="stats")
    frame, weights = small_run.get_distribution("m2")
    assert list(summary.index) == ["tsb", "tcb", "g"]
    # Rejection particles weigh the same: ArviZ's unweighted mean is the weighted one.
    np.testing.assert_allclose(summary.loc["tsb", "mean"], (frame["tsb"] * weights).sum(), atol=1e-3)


def test_arviz_summarises_an_smc_run_weighted_after_resampling(demo: bitrock.Record) -> None:
    import arviz as az

    run = bitrock.abc(demo, particles=400, sampler="smc", laws=["m2"], seed=5, backend="cpu", max_populations=4, progress=False)
    frame, weights = run.get_distribution("m2")
    assert weights.std() > 0, "SMC weights differ: the point of the test"
    node = run.to_datatree(resample=True)["m2"]
    draws = node["posterior"].to_dataset()["tsb"].values[0]
    # Systematic resampling draws each particle ⌊N·w⌋ or ⌈N·w⌉ times.
    values, drawn = np.unique(draws, return_counts=True)
    for value, n in zip(values, drawn):
        w = weights[frame["tsb"].to_numpy() == value].sum()
        assert np.floor(len(weights) * w) - 1e-9 <= n <= np.ceil(len(weights) * w) + 1e-9
    major = int(az.__version__.split(".")[0])
    data = node if major >= 1 else az.InferenceData.from_datatree(node)
    summary = az.summary(data, kind="stats")
    x = frame["tsb"].to_numpy()
    weighted = float((x * weights).sum())
    # Within three standard errors of the weighted mean (systematic resampling is tighter).
    assert abs(draws.mean() - weighted) <= 3 * x.std() / np.sqrt(len(x))
    assert summary.loc["tsb", "mean"] == pytest.approx(draws.mean(), abs=1e-3)
    assert np.array_equal(node["sample_stats"].to_dataset()["weight"].values[0], np.full(len(weights), 1 / len(weights)))
    assert run.to_datatree(resample=50)["m2"]["posterior"].to_dataset().sizes["draw"] == 50
    with pytest.raises(bitrock.InputError) as caught:
        run.to_datatree(resample=0)
    assert caught.value.argument == "resample"


def test_systematic_resampling_draws_each_particle_by_its_weight() -> None:
    from bitrock import _systematic_resample

    weights = np.array([0.5, 0.0, 0.3, 0.15, 0.05])
    for count in (1, 7, 20, 1000):
        drawn = np.bincount(_systematic_resample(weights, count), minlength=len(weights))
        assert drawn.sum() == count
        assert (np.floor(count * weights) <= drawn).all() and (drawn <= np.ceil(count * weights)).all(), (count, drawn)
    assert np.bincount(_systematic_resample(weights * 7.0, 20), minlength=5).tolist() == [10, 0, 6, 3, 1]
