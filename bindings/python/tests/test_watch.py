"""bitrock.watch gives the command line's windows, one update at a time, and a history."""

from __future__ import annotations

import gc
import json
import signal

import pytest

import bitrock
from conftest import run_cli

WELL = """sample_hz = 20
noise_torque_knm = 0.3
noise_speed_rpm = 0.5
seed = 5

[[segment]]
duration_s = 60
law = "m2"
omega_rpm = 60

[[segment]]
duration_s = 60
law = "m3"
omega_rpm = 60
"""

SETTINGS = ["--laws", "m2,m3", "--window-s", "20", "--step-s", "10", "--backend", "cpu", "--particles", "150"]


@pytest.fixture(scope="module")
def well(cli, tmp_path_factory):
    directory = tmp_path_factory.mktemp("well")
    (directory / "well.toml").write_text(WELL)
    run_cli(cli, "simulate", "--well", str(directory / "well.toml"), "-o", str(directory / "well.csv"))
    return directory / "well.csv"


def test_the_updates_are_the_command_lines(cli, well) -> None:
    watch = bitrock.watch(well, laws=["m2", "m3"], window_s=20, step_s=10, backend="cpu", particles=150)
    updates = list(watch)
    lines = [json.loads(line) for line in run_cli(cli, "watch", str(well), "--json", *SETTINGS).stdout.splitlines()]
    assert len(updates) == len(lines) == 11
    for ours, theirs in zip(updates, lines):
        for key in ("window", "start_s", "end_s", "samples_used", "most_probable", "change", "laws", "advice"):
            assert ours.document[key] == theirs[key], key
    history = watch.history
    assert list(history.index) == list(range(11))
    assert history.loc[0, "most_probable"] == "m2" and history.loc[10, "most_probable"] == "m3"
    assert history["change"].sum() == 1
    assert (history["p_m2"] + history["p_m3"]).round(12).eq(1.0).all()
    first = updates[0]
    assert first.most_probable == "m2" and list(first.laws.index) == ["m2", "m3"]
    # Every field of the line tab-completes as the attribute it is.
    assert set(first.document) <= set(dir(first)) and "laws" in dir(first)
    assert watch.ended["windows"] == 11


def test_thin_keeps_one_row_in_k_as_the_command_does(cli, well) -> None:
    # The 20 Hz well thinned by 2: windows of 20 s hold 200 rows, as `--thin 2` gives them.
    updates = list(bitrock.watch(well, laws="m2", thin=2, window_s=20, step_s=10, backend="cpu", particles=100))
    lines = run_cli(cli, "watch", str(well), "--json", "--thin", "2", "--laws", "m2", "--window-s", "20",
                    "--step-s", "10", "--backend", "cpu", "--particles", "100").stdout.splitlines()
    assert [u.document["samples"] for u in updates] == [json.loads(line)["samples"] for line in lines]
    assert all(u.document["samples"] == 200 for u in updates)
    assert [u.document["laws"] for u in updates] == [json.loads(line)["laws"] for line in lines]


def test_a_closed_watch_stops_reading(well) -> None:
    with bitrock.watch(well, laws="m2", window_s=20, step_s=10, backend="cpu", particles=100) as watch:
        for update in watch:
            if update.window == 1:
                break
    assert len(watch.history) == 2
    watch._thread.join(timeout=60)
    assert not watch._thread.is_alive()
    assert watch.ended["stopped"], "stopped before the record's end"


def test_a_stored_watch_goes_on_after_a_stop_as_if_it_never_stopped(well, tmp_path) -> None:
    settings = dict(laws=["m2", "m3"], window_s=20, step_s=10, backend="cpu", particles=100)
    whole = list(bitrock.watch(well, out=tmp_path / "whole", **settings))
    with bitrock.watch(well, out=tmp_path / "part", **settings) as watch:
        for update in watch:
            if update.window == 2:
                break
    watch._thread.join(timeout=60)
    stored = bitrock.read_watch(tmp_path / "part")
    # What was given is stored; the window in progress when it stopped may be stored too.
    assert 3 <= len(stored.updates) < 11
    resumed = list(bitrock.watch(well, out=tmp_path / "part", resume=True, **settings))
    assert [u.window for u in resumed] == list(range(len(stored.updates), 11))

    def numbers(updates):
        return [{k: v for k, v in u.document.items() if k != "latency_s"} for u in updates]

    assert numbers(bitrock.read_watch(tmp_path / "part").updates) == numbers(whole)
    assert numbers(bitrock.read_watch(tmp_path / "whole").updates) == numbers(whole)
    history = bitrock.read_watch(tmp_path / "part").history
    assert list(history.index) == list(range(11)) and history["change"].sum() == 1
    with pytest.raises(bitrock.InputError) as caught:
        list(bitrock.watch(well, out=tmp_path / "part", resume=True, **{**settings, "forgetting": 0.9}))
    assert caught.value.argument == "forgetting"
    with pytest.raises(bitrock.InputError) as caught:
        list(bitrock.watch(well, out=tmp_path / "part", **settings))
    assert caught.value.argument == "out"
    with pytest.raises(bitrock.InputError):
        bitrock.read_watch(tmp_path)


def test_refusals_name_their_argument(well, tmp_path) -> None:
    with pytest.raises(bitrock.InputError) as caught:
        list(bitrock.watch(well, window_s=10, step_s=20, backend="cpu"))
    assert caught.value.argument == "step_s"
    with pytest.raises(FileNotFoundError):
        list(bitrock.watch(tmp_path / "missing.csv"))


def test_the_paper_s_abc_on_each_window_is_the_command_s(cli, well) -> None:
    watch = bitrock.watch(
        well, laws="m2,m3", window_s=20, step_s=10, backend="cpu", abc=True, particles=1000, sampler="smc", seed=4
    )
    updates = list(watch)
    lines = run_cli(
        cli, "watch", str(well), "--json", "--laws", "m2,m3", "--window-s", "20", "--step-s", "10",
        "--backend", "cpu", "--abc", "--particles", "1000", "--sampler", "smc", "--seed", "4",
    ).stdout.splitlines()
    assert [u.document["laws"] for u in updates] == [json.loads(line)["laws"] for line in lines]
    for u in updates:
        assert u.epsilon == pytest.approx(0.014, abs=0) and u.laws["ln_z"].isna().all()
        assert u.laws["window_probability"].sum() == pytest.approx(1.0, abs=1e-12)
    assert watch.history["epsilon"].eq(0.014).all()
    # Settings of the procedure not used are refused, naming them.
    for wrong, argument in ((dict(delta=0.2), "delta"), (dict(abc=True, islands=3), "islands")):
        with pytest.raises(bitrock.InputError) as caught:
            list(bitrock.watch(well, laws="m2", backend="cpu", **wrong))
        assert caught.value.argument == argument


def test_the_advice_on_the_finite_element_string(cli, well, tmp_path) -> None:
    settings = dict(laws="m2", window_s=20, step_s=20, backend="cpu", particles=60)
    on_fe = list(bitrock.watch(well, structure="fe", out=tmp_path / "fe", **settings))
    one_dof = list(bitrock.watch(well, **settings))
    assert [u.document["laws"] for u in on_fe] == [u.document["laws"] for u in one_dof]
    critical = json.loads(run_cli(cli, "fe", "--json").stdout)["critical_bit_damping_nms"]
    criterion = bitrock.read_watch(tmp_path / "fe").meta["settings"]["criterion"]
    assert criterion == {"structure": "fe", "critical_bit_damping_nms": critical}
    with pytest.raises(bitrock.InputError) as caught:
        list(bitrock.watch(well, dp_elements=4, **settings))
    assert caught.value.argument == "dp_elements"


def test_the_live_page_serves_the_windows_as_they_come(well) -> None:
    import socket
    import urllib.request

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    watch = bitrock.watch(well, laws="m2", window_s=20, step_s=10, backend="cpu", particles=100, serve=f"127.0.0.1:{port}")
    seen = []
    for update in watch:
        seen.append(update.document)
        if len(seen) == 2:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/state.json", timeout=10) as r:
                state = json.load(r)
            # The page's history holds every window given so far (the watch may be ahead).
            assert state["updates"][:2] == seen
            assert state["meta"]["laws"][0]["name"] == "m2"
            assert state["view"] is not None and len(state["view"]["speed_rpm"]) > 0
    assert len(seen) == 11


def test_laws_are_refused_as_the_command_refuses_them(well) -> None:
    for laws in (["m2", "m2"], []):
        with pytest.raises(bitrock.InputError) as caught:
            list(bitrock.watch(well, laws=laws, backend="cpu", particles=100))
        assert caught.value.argument == "laws"
    with pytest.raises(bitrock.InputError, match="listed twice"):
        bitrock.fit(bitrock.read_record(), laws=["m2", "m2"])


def test_ctrl_c_in_the_loop_body_stops_the_watch(well) -> None:
    watch = bitrock.watch(well, laws="m2", window_s=20, step_s=10, backend="cpu", particles=100)
    # Taken as an interactive session takes it: the watches' handler (installed with the
    # process's first watch), then KeyboardInterrupt, even where the test runner, started in
    # the background, inherited SIGINT ignored.
    watches = signal.getsignal(signal.SIGINT)
    assert callable(watches)

    def interactive(signum, frame) -> None:
        watches(signum, frame)
        signal.default_int_handler(signum, frame)

    previous = signal.signal(signal.SIGINT, interactive)
    try:
        with pytest.raises(KeyboardInterrupt):
            for _ in watch:
                # As a Ctrl-C in the user's code between two updates: no code of the watch runs.
                signal.raise_signal(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, previous)
    watch._thread.join(timeout=60)
    assert not watch._thread.is_alive()
    assert watch.ended["stopped"] and watch.ended["windows"] < 11, watch.ended


def test_a_watch_no_one_holds_stops_reading(well) -> None:
    watch = bitrock.watch(well, laws="m2", window_s=20, step_s=10, backend="cpu", particles=100)
    next(watch)
    thread, outcome = watch._thread, watch._outcome
    del watch
    gc.collect()
    thread.join(timeout=60)
    assert not thread.is_alive()
    assert outcome["ended"]["stopped"] and outcome["ended"]["windows"] < 11, outcome

