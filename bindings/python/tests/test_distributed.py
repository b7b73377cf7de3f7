"""A run's populations and an evidence's samplers on a pool of workers (concurrent.futures,
Dask, Ray): the run store and the evidence of one process, bit for bit, whatever the number of
workers, the order tasks finish in, tasks lost and run again, or workers killed."""

from __future__ import annotations

import concurrent.futures
import json
import multiprocessing
import os
import random
import signal
import sqlite3
import threading
import time
from typing import Any

import numpy as np
import pytest

import bitrock
from test_identity import assert_same_particles

SPAWN = multiprocessing.get_context("spawn")
#: Columns and JSON keys that hold wall-clock times, which no two runs share.
CLOCK = ("seconds", "started_unix_s", "finished_unix_s", "created_unix_s")


def _without_clock(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_clock(v) for k, v in value.items() if k not in CLOCK and k != "threads"}
    if isinstance(value, list):
        return [_without_clock(v) for v in value]
    return value


def store_rows(run_dir: os.PathLike[str]) -> dict[str, list[tuple[Any, ...]]]:
    """Every row of a run store, wall-clock times left out (JSON cells parsed)."""
    connection = sqlite3.connect(os.path.join(run_dir, "run.sqlite"))
    tables = [r[0] for r in connection.execute("select name from sqlite_master where type='table' order by name")]
    rows = {}
    for table in tables:
        columns = [r[1] for r in connection.execute(f"pragma table_info({table})") if r[1] not in CLOCK]
        cells = connection.execute(f"select {', '.join(columns)} from {table} order by rowid").fetchall()
        rows[table] = [
            tuple(
                json.dumps(_without_clock(json.loads(c)), sort_keys=True) if isinstance(c, str) and c[:1] in "[{" else c
                for c in row
            )
            for row in cells
        ]
    connection.close()
    return rows


def assert_same_store(a: os.PathLike[str], b: os.PathLike[str]) -> None:
    rows_a, rows_b = store_rows(a), store_rows(b)
    assert rows_a.keys() == rows_b.keys()
    for table in rows_a:
        assert rows_a[table] == rows_b[table], table


SETTINGS = [
    {"particles": 400, "seed": 5, "max_populations": 4},
    {"particles": 400, "seed": 6, "sampler": "smc", "max_populations": 4},
]


@pytest.fixture(scope="module")
def one_process(demo: bitrock.Record, tmp_path_factory) -> list[os.PathLike[str]]:
    """The single-process runs of SETTINGS, stored."""
    dirs = []
    for k, settings in enumerate(SETTINGS):
        out = tmp_path_factory.mktemp("one") / f"run{k}"
        bitrock.abc(demo, backend="cpu", out=out, progress=False, **settings)
        dirs.append(out)
    return dirs


@pytest.mark.parametrize("k", range(len(SETTINGS)))
def test_a_process_pool_gives_the_one_process_store(demo, one_process, tmp_path, k) -> None:
    with concurrent.futures.ProcessPoolExecutor(2, mp_context=SPAWN) as pool:
        run = bitrock.abc(demo, backend="cpu", out=tmp_path / "pool", progress=False, executor=pool, **SETTINGS[k])
    assert_same_store(one_process[k], tmp_path / "pool")
    traffic = run.traffic
    # Every population this run scored has its row, and every round brought replies back.
    assert traffic is not None and len(traffic) > 0 and (traffic["reply_bytes"] > 0).all()
    # The record travels to a worker when it asks, not with every task: a scan task is a
    # range of candidate indices, a few dozen bytes.
    assert traffic["payload_bytes"].sum() > 0
    if SETTINGS[k].get("sampler") != "smc":
        assert (traffic["request_bytes"] / traffic["tasks"] < 100).all(), traffic


class Scrambled(concurrent.futures.Executor):
    """Threads that finish tasks in a shuffled order at uneven speeds, and lose the reply of
    the second task and every fifth after it (the task ran; its future fails), as a pool with
    slow and dying workers does."""

    def __init__(self, seed: int) -> None:
        self._pool = concurrent.futures.ThreadPoolExecutor(4)
        self._max_workers = 4
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._submitted = 0
        self.lost = 0

    def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
        with self._lock:
            delay = self._rng.random() * 0.01
            lose = self._submitted % 5 == 1
            self._submitted += 1

        def task():
            time.sleep(delay)
            reply = fn(*args, **kwargs)
            if lose:
                with self._lock:
                    self.lost += 1
                raise ConnectionError("worker lost")
            return reply

        return self._pool.submit(task)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._pool.shutdown(wait, cancel_futures=cancel_futures)


@pytest.mark.parametrize("k", range(len(SETTINGS)))
def test_uneven_workers_that_lose_tasks_give_the_one_process_store(demo, one_process, tmp_path, k) -> None:
    scrambled = Scrambled(seed=k)
    bitrock.abc(demo, backend="cpu", out=tmp_path / "s", progress=False, executor=scrambled, **SETTINGS[k])
    assert scrambled.lost > 0
    assert_same_store(one_process[k], tmp_path / "s")
    scrambled.shutdown()


def test_a_task_that_fails_every_try_stops_the_run_keeping_its_populations(demo, tmp_path) -> None:
    class Failing(Scrambled):
        def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
            def task():
                raise ConnectionError("no worker left")

            return self._pool.submit(task)

    with pytest.raises(bitrock.BitrockError, match="no worker left"):
        bitrock.abc(demo, backend="cpu", particles=300, seed=1, out=tmp_path / "f", progress=False, executor=Failing(0))


def test_ctrl_c_while_waiting_for_workers_keeps_the_run_resumable(demo, one_process, tmp_path) -> None:
    """Ctrl-C arrives while the driver waits for the workers of population 2 (here: raised by
    the executor): KeyboardInterrupt, the populations before it kept, and resuming on workers
    gives the uninterrupted run."""

    class Interrupting(Scrambled):
        def __init__(self) -> None:
            super().__init__(seed=3)
            self.population = -1

        def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
            if self.population == 2:
                raise KeyboardInterrupt
            return self._pool.submit(fn, *args, **kwargs)

    executor = Interrupting()

    def watch(population, *_rest) -> None:
        executor.population = population

    with pytest.raises(KeyboardInterrupt):
        bitrock.abc(demo, backend="cpu", out=tmp_path / "cut", progress=watch, executor=executor, **SETTINGS[1])
    with pytest.warns(bitrock.BitrockWarning, match=r"\(2 stored\)"):
        bitrock.resume(tmp_path / "cut", progress=False, executor=Scrambled(seed=4))
    # Everything but the invocations (this run had two: the interrupted start and the resume).
    rows, expected = store_rows(tmp_path / "cut"), store_rows(one_process[1])
    assert [r[1] for r in rows.pop("invocations")] == ["start", "resume"]
    expected.pop("invocations")
    assert rows == expected


def test_a_forking_process_pool_is_refused(demo) -> None:
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        with pytest.raises(bitrock.InputError, match="spawn"):
            bitrock.abc(demo, particles=100, progress=False, executor=pool)
    with pytest.raises(bitrock.InputError, match="executor"):
        bitrock.abc(demo, particles=100, progress=False, executor=object())
    # Which GPUs a worker uses is the worker's environment's to say.
    with pytest.raises(bitrock.InputError, match="devices: applies to a run in this process") as caught:
        bitrock.abc(demo, particles=100, progress=False, devices="all", executor=Scrambled(0))
    assert caught.value.argument == "devices"


def test_resume_on_workers_continues_as_one_process(demo, tmp_path) -> None:
    settings = {"particles": 400, "seed": 9, "sampler": "smc"}
    whole = bitrock.abc(demo, backend="cpu", max_populations=4, progress=False, **settings)
    bitrock.abc(demo, backend="cpu", max_populations=2, out=tmp_path / "r", progress=False, **settings)
    with concurrent.futures.ProcessPoolExecutor(2, mp_context=SPAWN) as pool:
        resumed = bitrock.resume(tmp_path / "r", max_populations=4, progress=False, executor=pool)
    assert_same_particles(whole, resumed)


def _score_on(backend: str) -> None:
    """A worker process's own backend, whatever the driver asks for."""
    os.environ["BITROCK_WORKER_BACKEND"] = backend


@pytest.mark.skipif(os.environ.get("BITROCK_SKIP_GPU_TESTS") == "1", reason="BITROCK_SKIP_GPU_TESTS=1")
def test_cpu_and_lavapipe_workers_together_agree_within_the_parity_contract(demo, tmp_path) -> None:
    """Half the tasks are scored on the CPU, half on the GPU (lavapipe here). Backends may
    decide otherwise only on a candidate within the parity tolerance of ε, and this run has
    none (its near-threshold counts are 0), so its populations are the CPU run's: the same
    candidates with the same parameters, and ρ within the parity tolerance (GPU ρ is f32)."""
    settings = {"particles": 400, "seed": 5, "max_populations": 3}
    pools = [
        concurrent.futures.ProcessPoolExecutor(
            1, mp_context=SPAWN, initializer=_score_on, initargs=(backend,)
        )
        for backend in ("cpu", "gpu")
    ]

    class Alternating(concurrent.futures.Executor):
        """Sends new tasks to the two pools in turn, and a task sent again (with the payloads
        its worker asked for) to the pool that asked."""

        _max_workers = 2

        def __init__(self) -> None:
            self.pool_of: dict[bytes, int] = {}

        def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
            k = self.pool_of.setdefault(args[0], len(self.pool_of) % 2)
            return pools[k].submit(fn, *args, **kwargs)

    cpu = bitrock.abc(demo, backend="cpu", out=tmp_path / "cpu", progress=False, **settings)
    try:
        bitrock.abc(demo, backend="cpu", out=tmp_path / "mixed", progress=False, executor=Alternating(), **settings)
    finally:
        for pool in pools:
            pool.shutdown()
    assert [p["near_threshold"] for p in cpu.document["populations"]] == [0] * 3
    backends = sqlite3.connect(tmp_path / "mixed" / "run.sqlite").execute("select backend from invocations").fetchall()
    assert backends == [("cpu+gpu",)]
    mixed = bitrock.open_run(tmp_path / "mixed")
    assert len(mixed.populations) == 3
    for g in range(3):
        a, b = cpu.particles(g), mixed.particles(g)
        assert a.keys() == b.keys()
        for law in a:
            (_, params_a, weights_a, rho_a, index_a), (_, params_b, weights_b, rho_b, index_b) = a[law], b[law]
            assert np.array_equal(index_a, index_b) and np.array_equal(params_a, params_b)
            assert np.array_equal(weights_a, weights_b)
            assert np.allclose(rho_a, rho_b, rtol=1e-5, atol=0), np.max(np.abs(rho_a / rho_b - 1))
    for p, q in zip(cpu.document["populations"], mixed.document["populations"]):
        assert (p["draws"], p["accepted"], p["model_probabilities"]) == (q["draws"], q["accepted"], q["model_probabilities"])


@pytest.fixture(scope="module")
def dask_client():
    import distributed

    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.mark.parametrize("k", range(len(SETTINGS)))
def test_a_dask_cluster_gives_the_one_process_store(demo, one_process, dask_client, tmp_path, k) -> None:
    run = bitrock.abc(demo, backend="cpu", out=tmp_path / "dask", progress=False, executor=dask_client, **SETTINGS[k])
    assert_same_store(one_process[k], tmp_path / "dask")
    # Payloads are scattered to both workers at once, each exactly once: the record with
    # population 0, each previous population with the next (SMC).
    payloads = run.traffic["payload_bytes"]
    assert payloads.iloc[0] > 0 and payloads.iloc[0] % 2 == 0
    if SETTINGS[k].get("sampler") == "smc":
        assert (payloads.iloc[1:] > 0).all()
    else:
        assert (payloads.iloc[1:] == 0).all()


def test_a_dask_worker_killed_mid_population_changes_nothing(demo, one_process, dask_client, tmp_path) -> None:
    pids = list(dask_client.run(os.getpid).values())
    killed = []

    def kill_once(population, accepted, target, drawn, epsilon) -> None:
        # While population 2's tasks run: a moment after its first round was merged.
        if population == 2 and not killed:
            killed.append(pids[0])
            threading.Timer(0.01, os.kill, (pids[0], signal.SIGKILL)).start()

    bitrock.abc(demo, backend="cpu", out=tmp_path / "killed", progress=kill_once, executor=dask_client, **SETTINGS[1])
    assert killed
    assert_same_store(one_process[1], tmp_path / "killed")


def test_a_surface_run_on_dask_workers_is_the_one_process_run(dask_client, tmp_path) -> None:
    """The surface sampler's strings simulated on the cluster: the result of one process, and a
    surface directory stopped after two populations and continued there, the run it would
    have been."""
    path = tmp_path / "surface.csv"
    bitrock.simulate(
        "m2", omega_rpm=60, duration_s=120, settle_s=60, sample_hz=1, channels="surface", noise_torque_knm=0.2, seed=7
    ).to_csv(path, index=False)
    small = dict(
        laws=["m1", "m2"], particles=150, pilot=100, check_replicates=4, predictive_draws=20, advice=False,
        backend="cpu", seed=11,
    )
    here = bitrock.surface(path, max_populations=3, **small)
    there = bitrock.surface(path, max_populations=3, executor=dask_client, **small)
    # Every population's tasks on the workers; the record and the string travel once to each.
    traffic = there.pop("traffic")
    assert [t["population"] for t in traffic] == [0, 1, 2]
    assert all(t["tasks"] >= 2 for t in traffic)
    assert traffic[0]["payload_bytes"] > 0
    assert _without_clock(there) == _without_clock(here)
    first = bitrock.surface(path, max_populations=2, out=tmp_path / "run", executor=dask_client, **small)
    assert first["populations"] == 2
    continued = bitrock.resume_surface(tmp_path / "run", max_populations=3, executor=dask_client)
    continued.pop("traffic")
    assert _without_clock(continued) == _without_clock(here)


#: An evidence small enough for a test: two laws, every model of the residuals (the embedded
#: record's weight on bit varies, so four in all), each batch of a few hundred candidates, and
#: its check by one replicate per law.
EVIDENCE = {"laws": ["m2", "m4"], "particles": 150, "islands": 2, "seed": 3, "backend": "cpu", "check": 1}


@pytest.fixture(scope="module")
def thinned() -> bitrock.Record:
    """The embedded record, every fourth row: 672 calibration samples."""
    return bitrock.read_record(thin=4)


@pytest.fixture(scope="module")
def one_process_evidence(thinned: bitrock.Record) -> dict[str, Any]:
    return _without_clock(bitrock.evidence(thinned, **EVIDENCE).document)


def assert_same_evidence(one_process: dict[str, Any], evidence: bitrock.Evidence) -> None:
    document = _without_clock(evidence.document)
    assert len(document["noise_models"]) == 4 and len(document["check"]["rows"]) == 2
    assert document == one_process


@pytest.mark.parametrize("executor", ["process pool", "scrambled", "dask"])
def test_the_evidence_on_workers_is_the_one_process_evidence(thinned, one_process_evidence, executor, request) -> None:
    if executor == "dask":
        pool = request.getfixturevalue("dask_client")
        assert_same_evidence(one_process_evidence, bitrock.evidence(thinned, executor=pool, **EVIDENCE))
        return
    made = (
        concurrent.futures.ProcessPoolExecutor(2, mp_context=SPAWN) if executor == "process pool" else Scrambled(seed=7)
    )
    with made as pool:
        evidence = bitrock.evidence(thinned, executor=pool, **EVIDENCE)
    assert_same_evidence(one_process_evidence, evidence)
    if isinstance(made, Scrambled):
        # Batches were cut into several tasks, and replies lost and sent again.
        assert made.lost > 0 and made._submitted > 100


def test_an_evidence_directory_is_checked_on_workers_as_the_evidence_checks_itself(
    thinned, one_process_evidence, one_process, tmp_path
) -> None:
    """check_selection of an evidence directory on a pool scores on the pool, and its check
    is the one the evidence computed in one process with check=1; a run's check takes no pool."""
    settings = {k: v for k, v in EVIDENCE.items() if k != "check"}
    bitrock.evidence(thinned, out=tmp_path / "ev", **settings)
    with Scrambled(seed=5) as pool:
        matrix = bitrock.check_selection(tmp_path / "ev", replicates=1, progress=False, executor=pool)
    assert pool._submitted > 100 and pool.lost > 0
    document = _without_clock(matrix.attrs["document"])
    assert document["rows"] == one_process_evidence["check"]["rows"]
    assert _without_clock(bitrock.read_evidence(tmp_path / "ev").document["check"]) == document
    with Scrambled(seed=5) as pool:
        with pytest.raises(bitrock.InputError) as caught:
            bitrock.check_selection(one_process[0], replicates=1, progress=False, executor=pool)
    assert caught.value.argument == "executor" and pool._submitted == 0


def test_a_failing_pool_stops_the_evidence_with_the_workers_error(thinned) -> None:
    class Failing(Scrambled):
        def submit(self, fn, /, *args, **kwargs):  # type: ignore[override]
            def task():
                raise ConnectionError("every worker lost")

            return self._pool.submit(task)

    with Failing(seed=1) as pool:
        with pytest.raises(bitrock.BitrockError, match="every worker lost"):
            bitrock.evidence(thinned, executor=pool, **EVIDENCE)


def test_ray_actors_give_the_one_process_store(demo, thinned, one_process, one_process_evidence, tmp_path) -> None:
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        executor = bitrock.ray_executor(2, env={"RAYON_NUM_THREADS": "1"})
        for k, settings in enumerate(SETTINGS):
            bitrock.abc(demo, backend="cpu", out=tmp_path / f"ray{k}", progress=False, executor=executor, **settings)
            assert_same_store(one_process[k], tmp_path / f"ray{k}")
        assert_same_evidence(one_process_evidence, bitrock.evidence(thinned, executor=executor, **EVIDENCE))
        executor.shutdown()
    finally:
        ray.shutdown()
