"""A run's populations on a pool of workers: a ``concurrent.futures`` executor, a Dask
``Client`` (and through it dask-jobqueue's Slurm/PBS clusters), or Ray actors.

The library cuts each round of a population into tasks (bytes), and :class:`Dispatcher`
carries them to the workers and their replies back. A worker answers a task with
:func:`serve_task`; it keeps the run's record and the previous population between tasks,
so that they travel once per worker, not once per task: a worker that lacks them says so,
and the task is sent again with them. On Dask they are scattered to every worker instead, and
every task names them. A task that fails on a worker (the worker was lost)
is sent again, up to ``retries`` times: tasks are pure, so a repeat gives the same reply.
"""

from __future__ import annotations

import concurrent.futures
import os
import threading
from typing import Any, Callable

from . import _bitrock
from ._errors import BitrockError, InputError

__all__ = ["Dispatcher", "RayExecutor", "ray_executor", "serve_task"]


def serve_task(request: bytes, problem: bytes | None = None, context: bytes | None = None) -> bytes:
    """What a worker runs: one task, answered by the bitrock of the worker's process."""
    return _bitrock.serve(request, problem, context)


def _is_dask_client(executor: Any) -> bool:
    return hasattr(executor, "get_executor") and hasattr(executor, "nthreads") and hasattr(executor, "scatter")


def _submitter(executor: Any) -> tuple[Callable[..., concurrent.futures.Future], int]:
    """The ``submit`` of ``executor`` (returning ``concurrent.futures`` futures) and its
    number of worker slots."""
    if _is_dask_client(executor):
        # dask.distributed.Client: its executor view gives concurrent.futures futures.
        slots = sum(executor.nthreads().values()) or 1
        return executor.get_executor(pure=False).submit, slots
    if not isinstance(executor, concurrent.futures.Executor):
        raise InputError(
            "executor: expected a concurrent.futures.Executor, a dask.distributed.Client or "
            f"bitrock.ray_executor(...), got {type(executor).__name__}",
            "executor",
        )
    if isinstance(executor, concurrent.futures.ProcessPoolExecutor):
        context = getattr(executor, "_mp_context", None)
        if context is not None and context.get_start_method() == "fork":
            raise InputError(
                "executor: a ProcessPoolExecutor that forks copies this process's thread pools "
                "half-made, and its workers hang; create it with "
                "mp_context=multiprocessing.get_context('spawn') (or 'forkserver')",
                "executor",
            )
    slots = getattr(executor, "_max_workers", None) or os.cpu_count() or 1
    return executor.submit, slots


class Dispatcher:
    """Carries the tasks of a run to ``executor``'s workers (see the module's text)."""

    def __init__(self, executor: Any, *, tasks_per_worker: int = 2, retries: int = 3) -> None:
        self._submit, self._workers = _submitter(executor)
        self._tasks_per_worker = tasks_per_worker
        self.retries = retries
        # A Dask client places the payloads on every worker itself (scatter, broadcast): each
        # travels once per worker, and every task names it.
        self._client = executor if _is_dask_client(executor) else None
        self._scattered: dict[str, tuple[int | None, Any]] = {}

    @property
    def parallelism(self) -> int:
        """Tasks a round is cut into: a few per worker slot. A Dask cluster is asked each
        round, so that workers that joined since (dask-jobqueue jobs starting) get work."""
        slots = sum(self._client.nthreads().values()) if self._client is not None else self._workers
        return max(1, slots * self._tasks_per_worker)

    def _on_every_worker(self, role: str, payload: bytes, key: int | None) -> tuple[Any, int]:
        """A Dask future of ``payload`` (named ``key``) held by every worker, and the bytes
        that took (0 when the same payload is held already)."""
        held = self._scattered.get(role)
        if held is not None and held[0] == key:
            return held[1], 0
        workers = len(self._client.scheduler_info()["workers"])
        future = self._client.scatter(payload, broadcast=True, hash=False)
        self._scattered[role] = (key, future)
        return future, len(payload) * workers

    def exchange(
        self,
        requests: list[bytes],
        problem: bytes,
        context: bytes | None,
        keys: tuple[int, int | None] = (0, None),
    ) -> tuple[list[bytes], int]:
        """The replies to ``requests`` in their order, and the payload bytes shipped;
        ``keys`` name the problem and the context (the same key, the same bytes)."""
        replies: list[bytes | None] = [None] * len(requests)
        pending: dict[concurrent.futures.Future, tuple[int, int, bool]] = {}
        shipped = 0
        payloads = (problem, context)

        def place() -> int:
            """On Dask: the payloads on every worker, named by the tasks; the bytes sent."""
            nonlocal problem, context
            problem, sent = self._on_every_worker("problem", payloads[0], keys[0])
            if payloads[1] is not None:
                context, more = self._on_every_worker("context", payloads[1], keys[1])
                sent += more
            return sent

        if self._client is not None:
            shipped += place()

        def send(i: int, tries: int, attach: bool) -> None:
            args = (requests[i], problem, context) if attach else (requests[i],)
            pending[self._submit(serve_task, *args)] = (i, tries, attach)

        try:
            for i in range(len(requests)):
                send(i, 0, self._client is not None)
            while pending:
                done, _ = concurrent.futures.wait(pending, return_when=concurrent.futures.FIRST_COMPLETED)
                for future in done:
                    i, tries, attached = pending.pop(future)
                    try:
                        reply = future.result()
                    except Exception as error:  # a lost worker, a broken pool
                        if tries + 1 > self.retries:
                            raise BitrockError(
                                f"a task failed on {tries + 1} tries, the last with: {error!r}"
                            ) from error
                        if self._client is not None:
                            # The workers holding the payloads may be gone: place them again.
                            self._scattered.clear()
                            shipped += place()
                        send(i, tries + 1, attached)
                        continue
                    if _bitrock.needs_payloads(reply):
                        if attached:
                            raise BitrockError("a worker asked again for the payloads it was sent")
                        shipped += len(problem) + (len(context) if context is not None else 0)
                        send(i, tries, True)
                    else:
                        replies[i] = reply
        finally:
            for future in pending:
                future.cancel()
        return [r for r in replies if r is not None], shipped


class RayExecutor(concurrent.futures.Executor):
    """A ``concurrent.futures`` executor over Ray actors: each actor is one long-lived worker
    process that keeps its GPU context, its pipelines and the run's record between tasks
    (plain Ray tasks asking for a GPU start a fresh process every call). Tasks go to the actor
    with the fewest in flight. Make it with :func:`ray_executor`."""

    def __init__(self, actors: list[Any]) -> None:
        self._actors = actors
        self._in_flight = [0] * len(actors)
        self._lock = threading.Lock()
        self._max_workers = len(actors)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> concurrent.futures.Future:
        with self._lock:
            k = min(range(len(self._actors)), key=self._in_flight.__getitem__)
            self._in_flight[k] += 1
        future = self._actors[k].call.remote(fn, *args, **kwargs).future()

        def done(_: concurrent.futures.Future) -> None:
            with self._lock:
                self._in_flight[k] -= 1

        future.add_done_callback(done)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        import ray

        for actor in self._actors:
            ray.kill(actor)
        self._actors = []


def ray_executor(
    workers: int | None = None,
    *,
    num_cpus: float = 1,
    num_gpus: float = 0,
    env: dict[str, str] | None = None,
) -> RayExecutor:
    """``workers`` Ray actors (default: one per CPU Ray sees, or per GPU with ``num_gpus``),
    each asking for ``num_cpus`` CPUs and ``num_gpus`` GPUs, with ``env`` set in their
    processes (``BITROCK_WORKER_BACKEND``, ``RAYON_NUM_THREADS``...). Ray must be initialised
    (``ray.init(...)``); an actor that dies is restarted by Ray and its task sent again."""
    import ray

    if not ray.is_initialized():
        raise InputError("executor: call ray.init(...) before bitrock.ray_executor(...)", "executor")
    if workers is None:
        resources = ray.cluster_resources()
        workers = int(resources.get("GPU", 0) // num_gpus) if num_gpus else int(resources.get("CPU", 1) // num_cpus)
    if workers < 1:
        raise InputError(f"workers: must be at least 1, got {workers}", "workers")

    @ray.remote(max_restarts=-1)
    class _Worker:
        def call(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
            return fn(*args, **kwargs)

    options: dict[str, Any] = {"num_cpus": num_cpus, "num_gpus": num_gpus}
    if env:
        options["runtime_env"] = {"env_vars": dict(env)}
    return RayExecutor([_Worker.options(**options).remote() for _ in range(workers)])
