"""A growing record followed window by window, as ``bitrock watch`` follows it."""

from __future__ import annotations

import json
import os
import queue
import signal
import threading
import weakref
from typing import Any, Iterator, Sequence

import pandas as pd

from . import _bitrock

# What the reading thread puts on the queue after the last update.
_END = object()

# The stop events of the watches reading now, set by Ctrl-C wherever the main thread is.
_READING: "weakref.WeakSet[threading.Event]" = weakref.WeakSet()
_INTERRUPT_HANDLER_INSTALLED = False


def _stop_on_interrupt(stop: threading.Event) -> None:
    """Makes Ctrl-C stop the watch whose event is `stop`, then act as it did before (by
    default, KeyboardInterrupt in the main thread): a Ctrl-C in the body of a loop over the
    updates, which no code of the watch's sees, stops it too. Signal handlers are the main
    thread's: a watch made on another thread stops by close() or garbage collection."""
    global _INTERRUPT_HANDLER_INSTALLED
    _READING.add(stop)
    if _INTERRUPT_HANDLER_INSTALLED or threading.current_thread() is not threading.main_thread():
        return
    previous = signal.getsignal(signal.SIGINT)

    def on_interrupt(signum: int, frame: Any) -> None:
        for event in list(_READING):
            event.set()
        if callable(previous):
            previous(signum, frame)
        elif previous == signal.SIG_DFL:
            signal.default_int_handler(signum, frame)

    signal.signal(signal.SIGINT, on_interrupt)
    _INTERRUPT_HANDLER_INSTALLED = True


class WatchUpdate:
    """One window's update: the fields of ``bitrock watch --json``'s line as attributes
    (``window``, ``start_s``, ``end_s``, ``samples_used``, ``uninformative``,
    ``most_probable``, ``change``, ``change_nats``, ``advice``, ``candidates_scored``,
    ``epsilon`` (the tolerance of the window's ABC, ``None`` for the evidence), ``latency_s``,
    and, for a record of surface channels alone, ``check``: the check by re-simulation of the
    window's model choice, ``{"decided": law or None, "verdict": words}``), ``laws`` as a
    DataFrame indexed by law, and the whole line as ``document``."""

    def __init__(self, document: dict[str, Any]) -> None:
        self.document = document

    def __getattr__(self, name: str) -> Any:
        try:
            return self.__dict__["document"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __dir__(self) -> list[str]:
        """The line's fields beside the methods, so that they tab-complete."""
        return sorted({*super().__dir__(), *self.document})

    @property
    def laws(self) -> pd.DataFrame:
        """Per law: the carried ``probability``, this window's alone (``window_probability``),
        ``ln_z`` and ``ln_z_error`` (``None`` by the paper's ABC), the posterior ``mean``, ``map``, ``q01``, ``q99`` of its
        parameters (lists, in the record's torque unit) and ``ess``, the effective sample size
        of its weighted posterior particles."""
        frame = pd.DataFrame(self.document["laws"])
        return frame.set_index("law") if len(frame) else frame

    def __repr__(self) -> str:
        d = self.document
        if d["uninformative"] is not None:
            return f"<bitrock.WatchUpdate window {d['window']} ({d['start_s']:g}–{d['end_s']:g} s): uninformative: {d['uninformative']}>"
        change = ", change" if d["change"] else ""
        return f"<bitrock.WatchUpdate window {d['window']} ({d['start_s']:g}–{d['end_s']:g} s): {d['most_probable']}{change}>"


class Watch:
    """An iterator over the updates of a watch (see :func:`watch`); ``history`` holds those
    given so far as a DataFrame. The record is read on a thread of its own, which stops after
    the window in progress on :meth:`close` (``with`` closes on leaving the block), on Ctrl-C
    (in the loop over the updates or in its body, as the command stops on it), and when the
    watch object is garbage collected."""

    def __init__(self, source: str, options: dict[str, Any]) -> None:
        updates: queue.Queue[Any] = queue.Queue()
        stop = threading.Event()
        outcome: dict[str, Any] = {}
        self._updates = updates
        self._stop = stop
        self._outcome = outcome
        self._given: list[WatchUpdate] = []

        # The thread holds only the queue, the stop event and the outcome, never the watch
        # object: a watch no one holds any more is collected, and its finaliser stops the
        # thread. After a stop the window in progress is still given (and stored): the watch
        # sees the stop between rows and ends there, with its `ended` record.
        def on_update(line: str) -> None:
            updates.put(WatchUpdate(json.loads(line)))

        def follow() -> None:
            from . import _note

            try:
                outcome["ended"] = json.loads(_bitrock.watch(source, options, on_update, _note, stop.is_set))
                updates.put(_END)
            except BaseException as error:  # handed to the loop over the updates
                updates.put(error)

        weakref.finalize(self, stop.set)
        _stop_on_interrupt(stop)
        self._thread = threading.Thread(target=follow, name="bitrock-watch", daemon=True)
        self._thread.start()

    @property
    def ended(self) -> dict[str, Any] | None:
        """How the watch ended (``windows``, ``stopped``, …), once it has."""
        return self._outcome.get("ended")

    def __iter__(self) -> Iterator[WatchUpdate]:
        return self

    def close(self) -> None:
        """Stops the watch after the window in progress (``with bitrock.watch(...) as w:``
        closes it on leaving the block)."""
        self._stop.set()

    def __enter__(self) -> "Watch":
        return self

    def __exit__(self, *_exc: Any) -> None:
        self.close()

    def __next__(self) -> WatchUpdate:
        try:
            while True:
                try:
                    item = self._updates.get(timeout=0.1)
                    break
                except queue.Empty:
                    continue
        except KeyboardInterrupt:
            self._stop.set()
            raise
        if item is _END:
            raise StopIteration
        if isinstance(item, BaseException):
            if isinstance(item, KeyboardInterrupt) and self._stop.is_set():
                raise StopIteration
            raise item
        self._given.append(item)
        return item

    @property
    def history(self) -> pd.DataFrame:
        """One row per window given so far: its times, samples used, the most probable law,
        each law's carried probability (``p_m1``…), the change flag, the window's ABC tolerance
        ``epsilon`` (``None`` for the evidence), P(unstable) at the
        operating point, the window's ``stuck_share`` (bit below 1 rpm) and ``stick_slip_now``
        (stuck 1 % of the time or more: never called steady), and the advice in words."""
        return _history([u.document for u in self._given])


def _history(documents: list[dict[str, Any]]) -> pd.DataFrame:
    """The history table of windows' updates (see :attr:`Watch.history`)."""
    rows = []
    for d in documents:
        row = {
            "window": d["window"],
            "start_s": d["start_s"],
            "end_s": d["end_s"],
            "samples_used": d["samples_used"],
            "most_probable": d["most_probable"],
            "change": d["change"],
            "epsilon": d.get("epsilon"),
        }
        for law in d["laws"]:
            row[f"p_{law['law']}"] = law["probability"]
        advice = d["advice"] or {}
        row["p_unstable"] = advice.get("p_unstable")
        row["stuck_share"] = advice.get("stuck_share")
        row["stick_slip_now"] = advice.get("stick_slip_now")
        row["advice"] = advice.get("words")
        rows.append(row)
    frame = pd.DataFrame(rows)
    return frame.set_index("window") if len(frame) else frame


class StoredWatch:
    """A watch directory read back (:func:`read_watch`): ``meta`` (source, settings, window
    and step, the record's rate and torque unit), ``updates`` (one :class:`WatchUpdate` per
    stored window) and ``history`` (their table, as :attr:`Watch.history`)."""

    def __init__(self, meta: dict[str, Any], updates: list[WatchUpdate]) -> None:
        self.meta = meta
        self.updates = updates

    @property
    def history(self) -> pd.DataFrame:
        return _history([u.document for u in self.updates])

    def __repr__(self) -> str:
        return f"<bitrock.StoredWatch of {self.meta['source']}: {len(self.updates)} windows>"


def read_watch(directory: str | os.PathLike[str]) -> StoredWatch:
    """Reads the watch stored in ``directory`` (``bitrock watch --out`` or
    ``bitrock.watch(out=...)``), while it runs or after."""
    meta, updates = _bitrock.read_watch(os.fspath(directory))
    return StoredWatch(json.loads(meta), [WatchUpdate(json.loads(u)) for u in updates])


def watch(
    source: str | os.PathLike[str],
    *,
    laws: str | Sequence[str] | None = None,
    thin: int | None = None,
    window_s: float | None = None,
    step_s: float | None = None,
    follow: bool = False,
    replay_speed: float | None = None,
    forgetting: float | None = None,
    floor: float | None = None,
    change_nats: float | None = None,
    risk: float | None = None,
    particles: int | None = None,
    islands: int | None = None,
    abc: bool = False,
    sampler: str | None = None,
    delta: float | None = None,
    eps_min: float | None = None,
    seed: int | None = None,
    backend: str | None = None,
    speed_col: str | None = None,
    torque_col: str | None = None,
    wob_col: str | None = None,
    time_col: str | None = None,
    speed_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    min_speed_rpm: float | None = None,
    out: str | os.PathLike[str] | None = None,
    resume: bool = False,
    wits_items: str | None = None,
    cold_start: bool = False,
    serve: str | None = None,
    structure: str | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    fe_file: str | os.PathLike[str] | None = None,
    dp_elements: int | None = None,
    bha_elements: int | None = None,
    alpha: float | None = None,
    beta: float | None = None,
) -> Watch:
    """Follows a record window by window as ``bitrock watch`` does (docs/watch.md): ``source``
    a CSV path (read whole; ``follow=True`` as it grows; ``replay_speed`` at that many times the
    pace of its time column), ``"-"`` for standard input, or ``"tcp://HOST:PORT"`` for a feed
    (CSV lines or WITS level-0 blocks, whose items ``wits_items`` names as the command's
    ``--wits-items``). Returns a :class:`Watch`: iterate
    it for one :class:`WatchUpdate` per window as each completes; ``.history`` is the
    DataFrame of those given. ``out`` is a watch directory where every window is stored as it
    finishes (``bitrock report`` draws it); ``resume=True`` goes on with the watch stored there
    after its last window. ``serve="127.0.0.1:8080"`` serves the live page of the watch there
    while it runs (its address said through the notes). ``structure`` decides the advice's
    stability as in :func:`stability`: ``"1dof"`` (the paper's, with ``inertia_kg_m2``,
    ``omega_n_rad_s``, ``damping_ratio``) or ``"fe"`` (the finite-element string, the paper's or
    ``fe_file``'s, with its overrides; its critical bit damping is found once, before the first
    window). ``abc=True`` gives each window's law probabilities by the paper's ABC instead of
    the evidence (``sampler``, ``particles``, ``delta``, ``eps_min`` as for :func:`abc`; each
    update's ``epsilon`` is the tolerance its window ended at, and its laws have no ``ln_z``).
    A record of surface channels alone (a top-drive speed and a surface torque, no bit channel;
    or a WITS feed whose ``wits_items`` name ``surface_torque``) goes window by window through
    simulated strings as :func:`surface` does (``particles`` per population, window k seeded
    ``seed`` + k): each update's ``check`` is its model choice's check by re-simulation, and its
    advice starts from the bit the surface implies.
    Keyword arguments are the command's flags without dashes."""
    from . import _law_names

    options = {k: v for k, v in locals().items() if k not in ("source", "_law_names")}
    options["laws"] = _law_names(laws)
    if out is not None:
        options["out"] = os.fspath(out)
    if fe_file is not None:
        options["fe_file"] = os.fspath(fe_file)
    return Watch(os.fspath(source), options)
