"""How a run scales over worker processes: the same run (rejection or SMC, the embedded record,
CPU backend) in one process, on 1 and on 2 single-threaded worker processes (a spawning
ProcessPoolExecutor), and on a local Dask cluster of 2 single-threaded workers. Prints, per
set-up, the median seconds of ``--reps`` runs and, per population of the first repetition, the
tasks, the bytes shipped and the driver's serial seconds (the population's seconds less the time
it waited for the workers). A warm-up run ships the record to the workers; its bytes are
printed once. Every run's particles are checked against the one-process run's. With
``--evidence``, the model evidence of the four laws instead (i.i.d. residuals, ``--particles``
per island, 4 islands), each checked against the one-process evidence.

    python bindings/python/benches/scale_out.py --particles 1000000 --populations 2 --reps 3
    python bindings/python/benches/scale_out.py --evidence --particles 500 --reps 3
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import os
import platform
import statistics
import time

import numpy as np

import bitrock


def _single_threaded() -> None:
    os.environ["RAYON_NUM_THREADS"] = "1"


def _same(a: bitrock.Result, b: bitrock.Result) -> bool:
    for g in range(len(a.populations)):
        pa, pb = a.particles(g), b.particles(g)
        if pa.keys() != pb.keys():
            return False
        for law in pa:
            if not all(np.array_equal(x, y) for x, y in zip(pa[law][1:], pb[law][1:])):
                return False
    return len(a.populations) == len(b.populations)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=1_000_000)
    parser.add_argument("--populations", type=int, default=2)
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--sampler", default="rejection")
    parser.add_argument("--evidence", action="store_true", help="the model evidence instead of a run")
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    record = bitrock.read_record()
    if args.evidence:
        evidence_scale_out(record, args)
        return
    settings = dict(
        particles=args.particles,
        max_populations=args.populations,
        sampler=args.sampler,
        seed=1,
        backend="cpu",
        progress=False,
    )
    spawn = multiprocessing.get_context("spawn")

    def one_process():
        return None, lambda: None

    def pool(workers):
        def make():
            executor = concurrent.futures.ProcessPoolExecutor(workers, mp_context=spawn, initializer=_single_threaded)
            return executor, executor.shutdown

        return make

    def dask(workers):
        def make():
            import distributed

            cluster = distributed.LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                env={"RAYON_NUM_THREADS": "1"},
            )
            client = distributed.Client(cluster)

            def close() -> None:
                client.close()
                cluster.close()

            return client, close

        return make

    setups = [
        ("one process (rayon, all cores)", one_process),
        ("ProcessPool, 1 worker × 1 thread", pool(1)),
        ("ProcessPool, 2 workers × 1 thread", pool(2)),
        ("Dask LocalCluster, 2 workers × 1 thread", dask(2)),
    ]
    reference = bitrock.abc(record, **settings)
    figures = []
    for name, make in setups:
        executor, close = make()
        # A first run warms the workers (process start, imports): the medians are of runs on
        # warm workers, as a long job sees them.
        record_bytes = 0
        if executor is not None:
            warm = bitrock.abc(record, **{**settings, "particles": 1000, "max_populations": 1}, executor=executor)
            record_bytes = int(warm.traffic["payload_bytes"].sum())
        seconds, results = [], []
        for _ in range(args.reps):
            started = time.perf_counter()
            results.append(bitrock.abc(record, **settings, executor=executor))
            seconds.append(time.perf_counter() - started)
        identical = all(_same(reference, r) for r in results)
        # The first repetition's traffic: later ones find the previous populations already held
        # by the workers (the same run again), which a new run would not.
        result = results[0]
        traffic = result.traffic
        row = {
            "setup": name,
            "median_s": statistics.median(seconds),
            "runs_s": seconds,
            "identical": identical,
            "record_payload_bytes": record_bytes,
        }
        if traffic is not None:
            pops = result.populations
            serial = [pops.loc[g, "seconds"] - traffic.loc[g, "wait_seconds"] for g in traffic.index]
            row["per_population"] = [
                {
                    "population": int(g),
                    "tasks": int(traffic.loc[g, "tasks"]),
                    "request_bytes": int(traffic.loc[g, "request_bytes"]),
                    "payload_bytes": int(traffic.loc[g, "payload_bytes"]),
                    "reply_bytes": int(traffic.loc[g, "reply_bytes"]),
                    "driver_serial_s": float(s),
                    "population_s": float(pops.loc[g, "seconds"]),
                }
                for g, s in zip(traffic.index, serial)
            ]
        figures.append(row)
        close()
        print(
            f"{name}: median {row['median_s']:.2f} s of {[round(s, 2) for s in seconds]}, identical: {identical}"
            + (f", record shipped: {record_bytes} B in all" if executor is not None else ""),
            flush=True,
        )
        for p in row.get("per_population", []):
            print(
                f"    population {p['population']}: {p['tasks']} tasks, requests {p['request_bytes']} B, "
                f"payloads {p['payload_bytes']} B, replies {p['reply_bytes']} B, "
                f"driver serial {p['driver_serial_s']:.3f} s of {p['population_s']:.2f} s",
                flush=True,
            )
    _report(
        f"--particles {args.particles} --populations {args.populations} --reps {args.reps} --sampler {args.sampler}",
        figures,
        args.json,
    )


def _report(flags: str, figures: list, path: str | None) -> None:
    """Prints the command, machine, version and date, and writes them with ``figures`` to
    ``path`` where given."""
    meta = {
        "command": f"python bindings/python/benches/scale_out.py {flags}",
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.platform()}",
        "bitrock": bitrock.__version__,
        "date": time.strftime("%Y-%m-%d"),
    }
    print(json.dumps(meta))
    if path:
        with open(path, "w") as out:
            json.dump({"meta": meta, "figures": figures}, out, indent=2)


def _without_seconds(value):
    if isinstance(value, dict):
        return {k: _without_seconds(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_without_seconds(v) for v in value]
    return value


def evidence_scale_out(record: bitrock.Record, args: argparse.Namespace) -> None:
    """The evidence of the four laws in one process and on 1 and 2 single-threaded worker
    processes: median seconds of ``args.reps``, each checked against the one-process one."""
    settings = dict(particles=args.particles, islands=4, seed=1, backend="cpu", noise="iid")
    spawn = multiprocessing.get_context("spawn")
    reference = _without_seconds(bitrock.evidence(record, **settings).document)
    figures = []
    for name, workers in [("one process (rayon, all cores)", 0), ("ProcessPool, 1 worker × 1 thread", 1),
                          ("ProcessPool, 2 workers × 1 thread", 2)]:
        executor = None
        if workers:
            executor = concurrent.futures.ProcessPoolExecutor(workers, mp_context=spawn, initializer=_single_threaded)
            bitrock.evidence(record, **{**settings, "particles": 50}, executor=executor)  # warm the workers
        seconds, identical = [], True
        for _ in range(args.reps):
            started = time.perf_counter()
            done = bitrock.evidence(record, **settings, executor=executor)
            seconds.append(time.perf_counter() - started)
            identical &= _without_seconds(done.document) == reference
        if executor is not None:
            executor.shutdown()
        figures.append({"setup": name, "median_s": statistics.median(seconds), "runs_s": seconds, "identical": identical})
        print(f"{name}: median {statistics.median(seconds):.2f} s of {[round(s, 2) for s in seconds]}, "
              f"identical: {identical}", flush=True)
    _report(f"--evidence --particles {args.particles} --reps {args.reps}", figures, args.json)


if __name__ == "__main__":
    main()
