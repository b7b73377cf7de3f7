"""bitrock from Python: calibrate and select drill-string bit-rock interaction laws by
Approximate Bayesian Computation, on the same engine (and with the same numbers) as the
``bitrock`` command line.

>>> import bitrock
>>> record = bitrock.read_record("field.csv")          # or a pandas DataFrame
>>> result = bitrock.abc(record, particles=5000, seed=1)
>>> result.model_probabilities                          # population × law
>>> df, w = result.get_distribution("m2")               # as pyABC's History gives it

Keyword arguments are named as the command line's flags without dashes (``eps_min`` for
``--eps-min``); an argument left at ``None`` takes the library's default.
"""

from __future__ import annotations

import json
import os
import pathlib
import re
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

# Mesa's device-select Vulkan layer only orders the Vulkan devices (bitrock ranks the adapters
# itself), and where no desktop session runs it prints "XDG_RUNTIME_DIR is invalid or not set"
# twice on the first GPU use: switched off unless the user set it, before the extension loads.
os.environ.setdefault("NODEVICE_SELECT", "1")

from . import _bitrock
from ._distributed import Dispatcher, ray_executor
from ._errors import BitrockError, BitrockWarning, GpuError, InputError
from ._evidence import Evidence, evidence, read_evidence, resume_evidence
from ._watch import StoredWatch, Watch, WatchUpdate, read_watch, watch
from . import plot

__all__ = [
    "BitrockError",
    "BitrockWarning",
    "GpuError",
    "InputError",
    "Record",
    "Result",
    "Evidence",
    "abc",
    "check_selection",
    "coupled",
    "coupled_calibrate",
    "coupled_select",
    "coupled_select_surface",
    "coupled_well",
    "evidence",
    "fit",
    "load_law",
    "open_run",
    "parity",
    "plot",
    "ray_executor",
    "read_evidence",
    "resume_evidence",
    "read_record",
    "resume",
    "simulate",
    "simulate_strings",
    "surface",
    "resume_surface",
    "read_surface",
    "stability",
    "torque",
    "watch",
    "read_watch",
    "StoredWatch",
    "Watch",
    "WatchUpdate",
]

__version__ = _bitrock.version()

Record = _bitrock.Record


# A population whose effective sample size is below this share of its particles is thin: the
# library's `abc::MIN_ESS_SHARE`, applied here to run.json documents that carry no `thin` flag.
_MIN_ESS_SHARE = 0.1

def read_record(
    source: str | os.PathLike[str] | pd.DataFrame | None = None,
    *,
    speed_col: str | None = None,
    torque_col: str | None = None,
    time_col: str | None = None,
    wob_col: str | None = None,
    speed_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    min_speed_rpm: float | None = None,
    t_start_s: float | None = None,
    t_end_s: float | None = None,
    thin: int | None = None,
    calibration_fraction: float | None = None,
    split: str | None = None,
    column_map: str | os.PathLike[str] | None = None,
    speed: Any = None,
    torque: Any = None,
    wob: Any = None,
    time: Any = None,
) -> Record:
    """Reads a record of bit speed and torque on bit (and weight on bit, time).

    ``source`` is a CSV path or a WITSML time log, a pandas DataFrame (its columns read as a
    CSV's would be), or ``None`` for the embedded demo record. ``column_map`` is a column map
    file naming a rig's columns and units by role, as ``--column-map`` (docs/records.md). Columns are found by name (``speed``, ``torque``,
    ``wob``, ``time``, or a rig log's mnemonic such as ``RPM_DH`` or ``TOB``) unless named; units
    come from the column names (``_rpm``, ``_knm``, ``_klbf``, ``TQ (kN.m)``) unless given
    (``rpm``, ``rad_s``, ``nm``, ``knm``, ``ftlbf``, ``kftlbf``, ``n``, ``kn``, ``lbf``, ``klbf``). A DataFrame's
    ``timedelta64`` column is read in seconds; a ``datetime64`` column, or one of ISO 8601 text
    stamps, in seconds since midnight UTC of its first row's day, as the command reads a
    record's wall clock. Rows below ``min_speed_rpm`` are dropped, and the rest split into calibration and
    validation samples (``calibration_fraction``, ``split`` ``"block"`` or ``"interleaved"``).
    What the record looks wrong in (a column whose values its unit can hardly mean, torques or
    speeds of the wrong sign, time running backwards) is raised as a ``BitrockWarning`` and kept
    in ``Record.warnings``.

    From arrays: ``read_record(speed=w, torque=t, speed_unit="rad_s", torque_unit="knm")``
    (and ``wob=`` with ``wob_unit``, ``time=`` in seconds), one-dimensional and of one length;
    arrays carry no names to read units from, so each unit must be given.
    """
    arrays = {"speed": speed, "torque": torque, "wob": wob, "time": time}
    options = {k: v for k, v in locals().items() if k not in ("source", "arrays", *arrays)}
    if column_map is not None:
        options["column_map"] = os.fspath(column_map)
    label = "<DataFrame>"
    if any(v is not None for v in arrays.values()):
        source, label = _arrays_frame(source, arrays, options), "<arrays>"
    if isinstance(source, pd.DataFrame):
        names = [str(c) for c in source.columns]
        record = _bitrock.read_columns(names, [_numbers(source.iloc[:, i]) for i in range(len(names))], label, options)
    else:
        record = _bitrock.read_csv(None if source is None else os.fspath(source), options)
    # What the record looks wrong in (a unit off by a thousand, flipped signs) is said where it
    # is read, once, as the command line says it; it stays in ``record.warnings``.
    for line in record.warnings:
        _note(line)
    return record


def _arrays_frame(source: Any, arrays: dict[str, Any], options: dict[str, Any]) -> pd.DataFrame:
    """The columns of ``read_record``'s array entry as a DataFrame read by the usual rules,
    after refusing what arrays cannot say: a source beside them, a missing speed or torque, a
    unit not given, a shape that is not one line of the speeds' length."""
    if source is not None:
        raise InputError("source: give a source or arrays (speed=, torque=), not both", "source")
    for name, unit in (("speed", "speed_unit"), ("torque", "torque_unit"), ("wob", "wob_unit")):
        if name in ("speed", "torque") and arrays[name] is None:
            raise InputError(f"{name}: the arrays entry needs both speed= and torque=", name)
        if arrays[name] is not None and options[unit] is None:
            raise InputError(f"{unit}: arrays have no column names to read units from; name the unit of {name}=", unit)
    columns = {}
    for name, values in arrays.items():
        if values is None:
            continue
        try:
            column = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{name}: give an array of numbers, got {type(values).__name__}", name) from None
        if column.ndim != 1:
            raise InputError(f"{name}: give a one-dimensional array, got shape {column.shape}", name)
        if columns and len(column) != len(next(iter(columns.values()))):
            raise InputError(f"{name}: {len(column)} values where speed has {len(next(iter(columns.values())))}", name)
        columns[name] = column
    for name in columns:
        if options.get(f"{name}_col") is not None:
            raise InputError(f"{name}_col: names a column of a file or DataFrame; the arrays are named by their keywords", f"{name}_col")
    if "time" in columns:
        columns["time_s"] = columns.pop("time")
    return pd.DataFrame(columns)


def _iso_stamps(column: pd.Series) -> bool:
    """Whether a text column holds ISO 8601 time stamps (its first value starts with a date)."""
    if not (pd.api.types.is_object_dtype(column) or pd.api.types.is_string_dtype(column)) or column.empty:
        return False
    first = column.iloc[0]
    return isinstance(first, str) and re.match(r"\s*\d{4}-\d{2}-\d{2}[T ]\d", first) is not None


def _numbers(column: pd.Series) -> np.ndarray | None:
    """A DataFrame column as contiguous float64 (missing values NaN, refused by the reader
    if the column is used), times in seconds; ``None`` when it holds no numbers."""
    if pd.api.types.is_timedelta64_dtype(column):
        return np.ascontiguousarray(column.dt.total_seconds().to_numpy(dtype=np.float64, na_value=np.nan))
    if _iso_stamps(column):
        column = pd.to_datetime(column, utc=True, format="ISO8601")
    if pd.api.types.is_datetime64_any_dtype(column):
        # The wall clock as the command reads it: s since midnight UTC of the first row's day
        # (a column without a zone read as UTC).
        utc = column.dt.tz_convert("UTC") if column.dt.tz is not None else column.dt.tz_localize("UTC")
        seconds = (utc - utc.iloc[0].floor("D")).dt.total_seconds()
        return np.ascontiguousarray(seconds.to_numpy(dtype=np.float64, na_value=np.nan))
    if pd.api.types.is_bool_dtype(column) or not pd.api.types.is_numeric_dtype(column):
        return None
    return np.ascontiguousarray(column.to_numpy(dtype=np.float64, na_value=np.nan))


def load_law(path: str | os.PathLike[str]) -> str:
    """Reads a law file (TOML: the law's name, its parameters with units and bounds, the torque
    as an expression of ``w``, ``r`` and the parameters; docs/law-files.md), compiles it for
    the CPU and the GPU, and returns the law's name, which ``laws=`` and ``law=`` then accept
    like ``m1``…``m4`` in this process. A run keeps the file's text: reading it back, resuming
    it or running it on workers does not need the file."""
    return _bitrock.load_law(os.fspath(path))


def _law_names(value: Any, argument: str = "laws") -> list[str] | None:
    """A list of law names from ``value``: ``None``, one name (``"m2"``), names separated by
    commas as the command takes them (``"m2,m3"``; no law's name holds a comma), or names."""
    if value is None:
        return None
    if isinstance(value, str):
        return [name.strip() for name in value.split(",")]
    try:
        names = list(value)
    except TypeError:
        raise InputError(f"{argument}: give a law name or a list of them, got {value!r}", argument) from None
    if not all(isinstance(name, str) for name in names):
        raise InputError(f"{argument}: law names are strings, got {value!r}", argument)
    return names


def _number_list(value: Any, argument: str) -> list[float] | None:
    """A list of numbers from ``value``: ``None``, one number, or numbers."""
    if value is None:
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [float(value)]
    if isinstance(value, (str, bytes)):
        raise InputError(f"{argument}: give a number or a list of numbers, got {value!r}", argument)
    try:
        items = list(value)
    except TypeError:
        raise InputError(f"{argument}: give a number or a list of numbers, got {value!r}", argument) from None
    if any(isinstance(item, bool) or not isinstance(item, (int, float, np.integer, np.floating)) for item in items):
        raise InputError(f"{argument}: every value must be a number, got {value!r}", argument)
    return [float(item) for item in items]


def _record(record: Any, argument: str = "record", optional: bool = False) -> Any:
    """``record`` if it is a record (or ``None`` where that is allowed); otherwise the refusal
    says how to make one."""
    if record is None and optional:
        return None
    if not isinstance(record, _bitrock.Record):
        raise InputError(
            f"{argument}: give a record made by bitrock.read_record (from a CSV file or a DataFrame), "
            f"got {type(record).__name__}",
            argument,
        )
    return record


def fit(
    record: Record,
    *,
    laws: str | Sequence[str] | None = None,
    bounds: bool = True,
    starts: int | None = None,
    scale_by_wob: bool = False,
    w_ref_kn: float | None = None,
) -> pd.DataFrame:
    """Least-squares fits of the laws (``m1``…``m4``; all by default) to the record's
    calibration samples: one row per law and parameter, with the estimate and its standard
    error in the record's torque unit, the misfit ρ on the calibration and validation
    samples, and the fit's warnings. ``bounds=False`` lifts the physical bounds;
    ``scale_by_wob`` scales each predicted torque by WOB / W_ref (``w_ref_kn``, kN)."""
    options = {"bounds": bounds, "starts": starts, "scale_by_wob": scale_by_wob, "w_ref_kn": w_ref_kn}
    doc = json.loads(_bitrock.fit(_record(record), _law_names(laws), options))
    rows = []
    for f in doc["fits"]:
        for name, unit, estimate, se in zip(f["names"], f["units"], f["params"], f["std_errors"]):
            rows.append(
                {
                    "law": f["law"],
                    "parameter": name,
                    "estimate": estimate,
                    "std_error": np.nan if se is None else se,
                    "unit": unit,
                    "rho": f["rho"],
                    "validation_rho": f["validation_rho"],
                    "warnings": list(f["warnings"]),
                }
            )
    return pd.DataFrame(rows)


def _progress(progress: bool | Callable[..., Any]) -> tuple[Callable[..., Any] | None, Callable[[], None]]:
    """The progress callback and its closer: a user's callable, or (when tqdm is installed) a
    bar per population that gives way, once the population is complete, to a line that stays:
    its ε, particles, draws and acceptance rate (in a notebook, a widget with ``ipywidgets``)."""
    if callable(progress):
        return progress, lambda: None
    if not progress:
        return None, lambda: None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, lambda: None
    bars: dict[int, Any] = {}
    seen: dict[int, tuple[int, int, int, float | None]] = {}

    def settle(population: int) -> None:
        bar = bars.pop(population, None)
        if bar is not None:
            bar.close()
        accepted, target, draws, epsilon = seen.pop(population)
        tqdm.write(_population_line(population, accepted, target, draws, epsilon))

    def update(population: int, accepted: int, target: int, draws: int, epsilon: float | None) -> None:
        for earlier in [g for g in seen if g != population]:
            settle(earlier)
        seen[population] = (accepted, target, draws, epsilon)
        bar = bars.get(population)
        if bar is None:
            bar = bars[population] = tqdm(total=target, desc=f"population {population} (ε {_epsilon_text(epsilon)})", leave=False)
        bar.update(accepted - bar.n)

    def close() -> None:
        for population in list(seen):
            settle(population)

    return update, close


def _epsilon_text(epsilon: float | None) -> str:
    return "∞" if epsilon is None else f"{epsilon:.5g}"


def _population_line(population: int, accepted: int, target: int, draws: int, epsilon: float | None) -> str:
    """The line a population leaves behind in the output."""
    if accepted < target:
        return f"population {population} (ε {_epsilon_text(epsilon)}): stopped at {accepted} of {target} particles, {draws} drawn"
    rate = accepted / draws if draws else 1.0
    return f"population {population} (ε {_epsilon_text(epsilon)}): {accepted} particles of {draws} drawn (acceptance {rate:.3g})"


def _note(line: str) -> None:
    """A line the library says once: information (which GPU scores, in which shape) is logged
    at INFO on the ``bitrock`` logger; anything else is a ``BitrockWarning``."""
    if _bitrock.is_information(line):
        import logging

        logging.getLogger("bitrock").info(line)
        return
    import warnings

    warnings.warn(line, BitrockWarning, stacklevel=3)


def abc(
    record: Record,
    *,
    laws: str | Sequence[str] | None = None,
    particles: int | None = None,
    sampler: str | None = None,
    epsilons: float | Sequence[float] | None = None,
    eps_min: float | None = None,
    start_epsilon: float | None = None,
    delta: float | None = None,
    prior_rule: str | None = None,
    prior_k: float | None = None,
    prior_file: str | os.PathLike[str] | None = None,
    max_populations: int | None = None,
    max_draws: int | None = None,
    min_acceptance: float | None = None,
    max_seconds: float | None = None,
    mode: str | None = None,
    p_stay: float | None = None,
    kernel_scale: float | None = None,
    smc_weights: str | None = None,
    refill: str | None = None,
    law_proposal: str | None = None,
    perturbation: str | None = None,
    bounds: bool = True,
    starts: int | None = None,
    scale_by_wob: bool = False,
    w_ref_kn: float | None = None,
    seed: int | None = None,
    backend: str | None = None,
    devices: str | None = None,
    structure: str | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    fe_file: str | os.PathLike[str] | None = None,
    dp_elements: int | None = None,
    bha_elements: int | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    out: str | os.PathLike[str] | None = None,
    force: bool = False,
    progress: bool | Callable[..., Any] = True,
    executor: Any = None,
) -> "Result":
    """ABC with model selection on ``record``: least-squares fits, a prior around them, then
    populations of the rejection sampler (the paper's Algorithm 1) or ABC-SMC down to the
    tolerance floor. Gives the particles ``bitrock abc`` gives with the same settings and
    seed. With ``out``, the run is written to that directory (``force`` replaces a run there)
    and can be continued with :func:`resume`; Ctrl-C stops it between batches, keeping the
    populations completed. ``progress``: a tqdm bar (when tqdm is installed), ``False``, or a
    callable ``(population, accepted, target, drawn, epsilon)``.

    ``devices="all"`` scores on every GPU of this machine, each a share of every round
    (``"one"``, the default: the GPU ``BITROCK_ADAPTER`` or ``CUDA_VISIBLE_DEVICES`` names).
    ``executor`` runs the populations' tasks on a pool of workers: a
    ``concurrent.futures.Executor`` (a ``ProcessPoolExecutor`` must spawn, not fork), a
    ``dask.distributed.Client``, or :func:`ray_executor`. The particles are the ones one
    process gives, bit for bit, whatever the number of workers, the order tasks finish in,
    or tasks lost and run again; :attr:`Result.traffic` says what travelled.

    ``structure``, ``inertia_kg_m2``, ``omega_n_rad_s``, ``damping_ratio`` and the finite-element
    string's ``fe_file``, ``dp_elements``, ``bha_elements``, ``alpha``, ``beta`` (as for
    :func:`stability`) give the drill string the run keeps: its maps and advice are drawn on it
    (the paper's 5 km field string where none is given)."""
    if executor is not None and devices is not None:
        raise InputError(
            "devices: applies to a run in this process; with `executor`, each worker uses the GPU "
            "its environment names (BITROCK_ADAPTER, CUDA_VISIBLE_DEVICES)",
            "devices",
        )
    record = _record(record)
    settings = {k: v for k, v in locals().items() if k not in ("record", "out", "force", "progress", "executor")}
    settings["laws"] = _law_names(laws)
    settings["epsilons"] = _number_list(epsilons, "epsilons")
    if settings["prior_file"] is not None:
        settings["prior_file"] = os.fspath(settings["prior_file"])
    if settings["fe_file"] is not None:
        settings["fe_file"] = os.fspath(settings["fe_file"])
    dispatcher = None if executor is None else Dispatcher(executor)
    callback, close = _progress(progress)
    try:
        run = _bitrock.abc(
            record,
            settings,
            None if out is None else os.fspath(out),
            force,
            callback,
            _note,
            dispatcher,
            1 if dispatcher is None else dispatcher.parallelism,
        )
    finally:
        close()
    return Result(run)


def resume(
    path: str | os.PathLike[str],
    *,
    eps_min: float | None = None,
    max_populations: int | None = None,
    max_draws: int | None = None,
    min_acceptance: float | None = None,
    max_seconds: float | None = None,
    backend: str | None = None,
    devices: str | None = None,
    progress: bool | Callable[..., Any] = True,
    executor: Any = None,
) -> "Result":
    """Continues the run in ``path`` (killed, interrupted or finished) with new stopping
    rules; the populations are those an uninterrupted run gives. ``executor`` as for
    :func:`abc`."""
    more = {
        "eps_min": eps_min,
        "max_populations": max_populations,
        "max_draws": max_draws,
        "min_acceptance": min_acceptance,
        "max_seconds": max_seconds,
        "backend": backend,
        "devices": devices,
    }
    if executor is not None and devices is not None:
        raise InputError(
            "devices: applies to a run in this process; with `executor`, each worker uses the GPU "
            "its environment names (BITROCK_ADAPTER, CUDA_VISIBLE_DEVICES)",
            "devices",
        )
    dispatcher = None if executor is None else Dispatcher(executor)
    callback, close = _progress(progress)
    try:
        run = _bitrock.resume(
            os.fspath(path),
            more,
            callback,
            _note,
            dispatcher,
            1 if dispatcher is None else dispatcher.parallelism,
        )
    finally:
        close()
    return Result(run)


def open_run(path: str | os.PathLike[str]) -> "Result":
    """The run in directory ``path``, as written by ``bitrock abc`` or :func:`abc`."""
    return Result(_bitrock.open_run(os.fspath(path)))


def stability(
    source: "Result | Evidence | str | os.PathLike[str] | None" = None,
    *,
    law: str | None = None,
    params: Sequence[float] | None = None,
    torque_unit: str | None = None,
    omega_rpm: "Sequence[float] | str | None" = None,
    wob_kn: "Sequence[float] | str | None" = None,
    structure: str | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    fe_file: str | os.PathLike[str] | None = None,
    dp_elements: int | None = None,
    bha_elements: int | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    w_ref_kn: float | None = None,
    percentile: float | None = None,
    samples: int | None = None,
    backend: str | None = None,
    simulate: bool = False,
    at_rpm: float | None = None,
    at_kn: float | None = None,
    sim_omega_rpm: "Sequence[float] | str | None" = None,
    sim_wob_kn: "Sequence[float] | str | None" = None,
    sim_samples: int | None = None,
    dt_s: float | None = None,
) -> Any:
    """Torsional stick-slip stability over top-drive speed Ω (rpm) and weight on bit W (kN),
    as ``bitrock stability`` computes it: for a run's last population (``source``, a
    :class:`Result`, in memory or written to a directory, or the directory), for the posterior of an
    :class:`Evidence` (``source``, or its evidence directory: each law weighed by its P(m | y)), for
    a surface directory's posterior (``bitrock.surface(..., out=DIR)``), or for one ``law`` at ``params``
    (its parameters in order, torques in ``torque_unit``, kN·m by default).

    Returns an ``xarray.Dataset`` over ``law`` × ``omega_rpm`` × ``wob_kn``:
    ``probability_unstable`` (the share of posterior samples unstable at each cell),
    ``map_wob_kn`` (the MAP's boundary: the weight on bit above which it is unstable, NaN where
    none), ``p_wob_kn`` (the ``percentile`` % boundary of the samples), ``mixture_p_wob_kn``
    when the run has several laws, and each law's ``probability``. ``structure``: ``"1dof"``
    (the paper's, with ``inertia_kg_m2``, ``omega_n_rad_s``, ``damping_ratio``) or ``"fe"``
    (the finite-element string, the paper's or ``fe_file``'s, with its overrides). Axes are
    values or ``"MIN:MAX:COUNT"``.

    With ``simulate=True``, also the maps by simulated strings, as ``bitrock stability
    --simulate`` makes them, over ``sim_omega_rpm`` × ``sim_wob_kn`` with ``sim_samples``
    posterior samples per law and step ``dt_s``: ``onset_probability`` (stick-slip develops from
    steady rotation kicked by a tenth of Ω) and, from ``at_rpm`` and ``at_kn`` (where the bit
    is now; a run's own record's operating point by default), ``escape_probability``
    (stick-slip persists from the state the bit is in there) and the advice in
    ``attrs["advice"]`` (``speed_rpm``, ``speed_end_probability``, ``wob_kn``,
    ``wob_end_probability``, the share of strings that left physical bounds there
    (``speed_diverged_share``, ``wob_diverged_share``: P(it ends) is then a lower bound),
    ``stick_slip_probability``, ``text``).

    For a run (written or kept in memory), ``attrs["record_advice"]`` is the advice at its
    record's own operating point (mean bit speed and weight on bit), as ``bitrock stability
    --run`` prints it: ``record`` (``stuck_share``, ``severity``, ``peak_speed_rpm``,
    ``mean_speed_rpm``, ``mean_wob_kn``, ``samples``) and ``advice`` (``words``,
    ``stick_slip_now``, ``escape_omega_rpm`` and ``escape_wob_kn`` as [value, P(it ends)] from
    the state the bit is in, ``cycle``: whether the posterior's strings reproduce the record's
    peak bit speed, ``p_unstable``, ``safe_omega_rpm``, ``safe_wob_kn``)."""
    import xarray as xr

    posterior = None
    run_in_memory = None
    if isinstance(source, Result):
        if source.path is None:
            run_in_memory = source._run
        source = source.path
    elif isinstance(source, (str, os.PathLike)) and _bitrock.is_evidence_dir(os.fspath(source)):
        source = read_evidence(source)
    if isinstance(source, Evidence):
        posterior = json.dumps(source.document)
        # Where the evidence scaled each torque by WOB / W_ref, its parameters are for W_ref.
        if w_ref_kn is None:
            w_ref_kn = source.document.get("w_ref_kn")
        source = None
    run = None if source is None else os.fspath(source)
    options = {k: v for k, v in locals().items() if k not in ("source", "law", "params", "run", "xr")}
    if options["fe_file"] is not None:
        options["fe_file"] = os.fspath(options["fe_file"])
    for key in ("omega_rpm", "wob_kn", "sim_omega_rpm", "sim_wob_kn"):
        if options[key] is not None and not isinstance(options[key], str):
            options[key] = [float(v) for v in options[key]]
    maps = _bitrock.stability(run, law, None if params is None else [float(p) for p in params], options, _note)
    laws = maps["laws"]
    variables = {
        "probability_unstable": (("law", "omega_rpm", "wob_kn"), maps["probability_unstable"]),
        "map_wob_kn": (("law", "omega_rpm"), maps["map_wob_kn"], {"units": "kN"}),
        "p_wob_kn": (("law", "omega_rpm"), maps["p_wob_kn"], {"units": "kN"}),
        "probability": ("law", np.asarray(maps["probability"])),
        "samples": ("law", np.asarray(maps["samples"])),
    }
    if "mixture_p_wob_kn" in maps:
        variables["mixture_p_wob_kn"] = ("omega_rpm", maps["mixture_p_wob_kn"], {"units": "kN"})
    coords = {
        "law": laws,
        "omega_rpm": ("omega_rpm", maps["omega_rpm"], {"units": "rpm"}),
        "wob_kn": ("wob_kn", maps["wob_kn"], {"units": "kN"}),
    }
    attrs = {
        "structure": maps["structure"],
        "critical_bit_damping_nms": maps["critical_bit_damping_nms"],
        "percentile": maps["percentile"],
    }
    if "onset_probability" in maps:
        coords["sim_omega_rpm"] = ("sim_omega_rpm", maps["sim_omega_rpm"], {"units": "rpm"})
        coords["sim_wob_kn"] = ("sim_wob_kn", maps["sim_wob_kn"], {"units": "kN"})
        for key in ("onset_probability", "escape_probability"):
            if key in maps:
                variables[key] = (("sim_omega_rpm", "sim_wob_kn"), maps[key])
        attrs["simulated_strings"] = maps["simulated_strings"]
        if "advice" in maps:
            attrs["advice"] = maps["advice"]
    if "record_advice" in maps:
        attrs["record_advice"] = json.loads(maps["record_advice"])
    return xr.Dataset(variables, coords=coords, attrs=attrs)


def check_selection(
    source: "Result | str | os.PathLike[str]",
    *,
    replicates: int | None = None,
    batch: int | None = None,
    backend: str | None = None,
    progress: bool | Callable[[int, int], Any] = True,
    executor: Any = None,
) -> pd.DataFrame:
    """How far the run's model selection can be trusted, as ``bitrock check-selection``
    measures it: ``replicates`` synthetic records per law, each made from the law's posterior
    (or least-squares estimate when it died out) with the record's noise, each run through the
    run's own procedure. Writes the check into the run's ``selection/`` directory (a run kept
    in memory is checked alike; its check is only returned). ``source`` may also be an
    evidence directory (``evidence(..., out=DIR)``): its evidence is computed again and checked
    as ``evidence(check=K)`` checks it, the check written into its document (``batch`` does not
    apply); ``executor`` (as for :func:`evidence`) then scores its candidates on a pool of
    workers, the same check as here. ``source`` may also be a surface directory
    (``surface(..., out=DIR)``): its check by re-simulation is made again with ``replicates``
    records per law from its stored populations and written into its document; the matrix then
    holds the share of each law's re-simulated records classified as each law, ``attrs`` its
    ``verdict``, ``decided`` and ``document`` (``batch`` and ``executor`` do not apply).

    Returns the confusion matrix: one row per generating law, one column per law, the mean
    posterior probability over its replicates. ``attrs`` holds ``first_share`` (the share of
    replicates in which each law ranks first, same shape), ``verdicts`` (a sentence per
    generating law) and ``document`` (the whole check). ``progress``: a tqdm bar over the
    replicates, ``False``, or a callable ``(done, total)``. The check runs to its end once
    started (Ctrl-C is seen when it returns)."""
    in_memory = None
    if isinstance(source, Result):
        if source.path is None:
            in_memory = source._run
        source = source.path
    elif not isinstance(source, (str, os.PathLike)):
        raise InputError(f"source: give a Result, a run, an evidence or a surface directory, got {type(source).__name__}", "source")
    if in_memory is None and _bitrock.is_surface_dir(os.fspath(source)):
        return _check_surface(os.fspath(source), replicates, batch, backend, executor)
    dispatcher = None if executor is None else Dispatcher(executor)
    callback, close = _replicate_progress(progress)
    try:
        document = json.loads(
            _bitrock.check_selection(
                None if source is None else os.fspath(source),
                in_memory,
                {"replicates": replicates, "batch": batch, "backend": backend},
                callback,
                _note,
                dispatcher,
                1 if dispatcher is None else dispatcher.parallelism,
            )
        )
    finally:
        close()
    laws = document["laws"]
    rows = [r["law"] for r in document["rows"]]
    matrix = pd.DataFrame([r["mean_probability"] for r in document["rows"]], index=pd.Index(rows, name="generating"), columns=pd.Index(laws, name="law"))
    first = pd.DataFrame([r["first_share"] for r in document["rows"]], index=matrix.index, columns=matrix.columns)
    matrix.attrs = {"first_share": first, "verdicts": {r["law"]: r["verdict"] for r in document["rows"]}, "document": document}
    return matrix


def _replicate_progress(progress: bool | Callable[[int, int], Any]) -> tuple[Callable[[int, int], Any] | None, Callable[[], None]]:
    """A selection check's progress: a user's callable, one tqdm bar over the replicates, or
    nothing."""
    if callable(progress):
        return progress, lambda: None
    if not progress:
        return None, lambda: None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, lambda: None
    bar: list[Any] = []

    def update(done: int, total: int) -> None:
        if not bar:
            bar.append(tqdm(total=total, desc="replicates", leave=False))
        bar[0].update(done - bar[0].n)

    def close() -> None:
        for b in bar:
            b.close()

    return update, close


def torque(
    law: str,
    speed_rad_s: "float | Sequence[float] | np.ndarray",
    params: Sequence[float],
    *,
    r: float = 1.0,
    torque_unit: str | None = None,
) -> np.ndarray:
    """The law's torque on bit r·T(w) at the bit speeds ``speed_rad_s`` (rad/s, any shape),
    its ``params`` in its order with torques in ``torque_unit`` (``"knm"``, the default, or
    ``"nm"``), at the weight-on-bit ratio ``r``; the torques in the same unit and shape (NaN
    where a law file's torque has no value)."""
    speeds = np.asarray(speed_rad_s, dtype=float)
    # ravel gives one contiguous row (copying only a strided or transposed array).
    values = _bitrock.torque(law, speeds.ravel(), [float(p) for p in params], float(r), torque_unit)
    return values.reshape(speeds.shape)


def simulate(
    law: str,
    *,
    omega_rpm: float,
    params: Sequence[float] | None = None,
    param_torque_unit: str | None = None,
    wob_kn: float | None = None,
    w_ref_kn: float | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    duration_s: float | None = None,
    settle_s: float | None = None,
    sample_hz: float | None = None,
    dt_s: float | None = None,
    initial: str | None = None,
    kick_rpm: float | None = None,
    noise_torque_knm: float | None = None,
    noise_speed_rpm: float | None = None,
    wob_fluctuation_kn: float | None = None,
    wob_correlation_s: float | None = None,
    seed: int | None = None,
    channels: str | None = None,
) -> pd.DataFrame:
    """A synthetic record of the paper's 1-DOF drill string driven at ``omega_rpm`` with
    ``law`` (at ``params`` in its order, torques in ``param_torque_unit``; the paper's estimate
    by default), as ``bitrock simulate`` writes it: a DataFrame with ``time_s``,
    ``bit_speed_rpm``, ``torque_knm`` and ``wob_kn``, sampled at ``sample_hz`` after
    ``settle_s``, with measurement noise and a fluctuating weight on bit when asked. It reads
    back with :func:`read_record`. A torque parameter beyond any drill bit's (1,000 kN·m) is
    simulated but warned of (a ``BitrockWarning``): values in N·m given as kN·m. ``channels``
    ``"surface"`` gives what a rig streams instead (``time_s``, ``top_drive_rpm``,
    ``surface_torque_knm``, ``wob_kn``), ``"all"`` both, ``"mwd"`` the surface's with an MWD
    tool's stick-slip channels (``downhole_min_rpm``, ``downhole_max_rpm``: the bit speed's
    least and greatest since the sample before), for :func:`surface`."""
    import io

    options = {k: v for k, v in locals().items() if k not in ("law", "params", "omega_rpm", "io")}
    text = _bitrock.simulate(law, None if params is None else [float(p) for p in params], float(omega_rpm), options, _note)
    return pd.read_csv(io.StringIO(text))


def surface(
    path: str | os.PathLike[str],
    *,
    laws: Sequence[str] | None = None,
    prior_file: str | os.PathLike[str] | None = None,
    prior_scale: float | None = None,
    time_col: str | None = None,
    top_drive_col: str | None = None,
    surface_torque_col: str | None = None,
    wob_col: str | None = None,
    top_drive_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    downhole_min_col: str | None = None,
    downhole_max_col: str | None = None,
    downhole_unit: str | None = None,
    downhole_window_s: float | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | tuple[float, float] | None = None,
    damping_ratio: float | tuple[float, float] | None = None,
    w_ref_kn: float | None = None,
    noise_sd_knm: float | None = None,
    particles: int | None = None,
    max_populations: int | None = None,
    max_seconds: float | None = None,
    pilot: int | None = None,
    check_replicates: int | None = None,
    predictive_draws: int | None = None,
    advice: bool | None = None,
    dt_s: float | None = None,
    settle_s: float | None = None,
    seed: int | None = None,
    backend: str | None = None,
    semi_automatic: bool | None = None,
    out: str | os.PathLike[str] | None = None,
    force: bool = False,
    executor: Any = None,
) -> dict:
    """The law at the bit from a surface record (top-drive speed, surface torque and weight on
    bit on a regular clock, a CSV file) through drill strings simulated per candidate, as
    ``bitrock surface`` infers it: a dict with the noise and how it was found, the cycle, each
    law's probability and parameters (SI, those the record leaves to the prior marked
    ``identified: False``), the check of the model choice by re-simulation and its verdict
    (``check["decided"]`` is ``None`` where the record cannot tell the laws apart), and
    ``at_the_bit``: the bit's speed band per sample of ``time_s`` (rpm), its stuck share overall
    and per law, P(stick-slip) and the escape advice. Where the rig also streams an MWD tool's
    downhole minimum or maximum bit speed (found by name, or ``downhole_min_col`` and
    ``downhole_max_col``, taken over ``downhole_window_s``), each string's is compared with it.
    The string is the paper's, or the one ``inertia_kg_m2``, ``omega_n_rad_s`` and
    ``damping_ratio`` give; a pair ``(lo, hi)`` for ``omega_n_rad_s`` or ``damping_ratio``
    infers it with the laws within those bounds (``string`` in the result: its posterior and
    the stiffness it implies). The strings are simulated on ``backend`` (``"auto"``: a hardware GPU
    where one is usable, else the CPU, whose lanes outrun a software GPU; ``"gpu"``, ``"cpu"``); the result's ``backend`` says
    where. ``semi_automatic=True`` compares what linear regressions on the pilot strings nearest
    the record predict from the summaries (each law's parameters, the string's where inferred,
    each law's probability) instead of the summaries: ``projection`` in the result names each
    prediction with its adjusted R². With ``out``, the run is written to that surface directory
    (``surface.json``, ``posterior.csv``, ``bit.csv``, and the record, job and populations that
    :func:`resume_surface` continues; ``force=True`` replaces a surface run there), as
    ``bitrock surface --out``. ``executor`` (as for :func:`abc`) simulates the sampler's
    strings on a pool of workers, the populations those of one process bit for bit;
    ``traffic`` in the result says what travelled. docs/surface.md says what a surface record
    can and cannot tell."""
    import json

    options = {k: v for k, v in locals().items() if k not in ("path", "laws", "json", "out", "force", "executor")}
    dispatcher = None if executor is None else Dispatcher(executor)
    text = _bitrock.surface(
        os.fspath(path),
        None if laws is None else [str(law) for law in laws],
        options,
        _note,
        None if out is None else os.fspath(out),
        force,
        dispatcher,
        1 if dispatcher is None else dispatcher.parallelism,
    )
    return json.loads(text)


def read_surface(directory: str | os.PathLike[str]) -> dict:
    """The finished surface run in ``directory`` (``bitrock.surface(..., out=directory)`` or
    ``bitrock surface --out``), as :func:`surface` returns it, without computing anything."""
    import json

    return json.loads(_bitrock.read_surface(os.fspath(directory)))


def _check_surface(directory: str, replicates: int | None, batch: int | None, backend: str | None, executor: Any) -> pd.DataFrame:
    """:func:`check_selection` of a surface directory."""
    import json

    for name, value in (("batch", batch), ("executor", executor)):
        if value is not None:
            raise InputError(f"{name}: applies to an ABC run's or an evidence's check, not a surface run's", name)
    check = json.loads(_bitrock.check_surface(directory, replicates, backend, _note))["check"]
    laws = [law for law, _ in check["rows"][0]["classified_as"]] if check["rows"] else []
    matrix = pd.DataFrame(
        [[count / row["replicates"] for _, count in row["classified_as"]] for row in check["rows"]],
        index=pd.Index([row["law"] for row in check["rows"]], name="generating"),
        columns=pd.Index(laws, name="law"),
    )
    matrix.attrs = {"verdict": check["verdict"], "decided": check["decided"], "document": check}
    return matrix


def resume_surface(
    directory: str | os.PathLike[str],
    *,
    max_populations: int | None = None,
    max_seconds: float | None = None,
    backend: str | None = None,
    check_replicates: int | None = None,
    executor: Any = None,
) -> dict:
    """Continues the surface run in ``directory`` (one that ``bitrock.surface(..., out=directory)``
    or ``bitrock surface --out`` wrote, finished or killed part-way) after its last stored
    population, with its record and settings: ``max_populations`` (the first and those stored
    included), ``max_seconds``, ``backend`` and ``check_replicates`` replace the run's own (and
    are kept for the next continuation). On the same backend the populations are those an
    uninterrupted run gives (on another, the run says its bits differ); the check and the bit are computed again
    and the directory written anew. Returns the result as :func:`surface` does. As ``bitrock
    surface --resume``; :func:`check_selection` of the directory checks it again without
    sampling. ``executor`` as for :func:`surface`."""
    import json

    dispatcher = None if executor is None else Dispatcher(executor)
    text = _bitrock.resume_surface(
        os.fspath(directory),
        max_populations,
        max_seconds,
        backend,
        check_replicates,
        _note,
        dispatcher,
        1 if dispatcher is None else dispatcher.parallelism,
    )
    return json.loads(text)


def coupled(
    *,
    omega_rpm: float | None = None,
    wob_kn: float | None = None,
    feed_m_h: float | None = None,
    radius_m: float | None = None,
    intrinsic_energy_mpa: float | None = None,
    zeta: float | None = None,
    contact_stress_mpa: float | None = None,
    wear_flat_mm: float | None = None,
    friction: float | None = None,
    gamma: float | None = None,
    blades: int | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    mass_kg: float | None = None,
    axial_stiffness_kn_m: float | None = None,
    axial_damping_kns_m: float | None = None,
    duration_s: float | None = None,
    settle_s: float | None = None,
    sample_hz: float | None = None,
    dt_s: float | None = None,
    kick_rpm: float | None = None,
    map_rpm: str | None = None,
    map_wob_kn: str | None = None,
    map_feed_m_h: str | None = None,
    escape: bool | None = None,
    samples: int | None = None,
    seed: int | None = None,
    backend: str | None = None,
    record: bool = False,
    map: bool = False,
) -> dict:
    """The coupled axial-torsional bit (Richard, Germay & Detournay) on the 1-DOF string, as
    ``bitrock coupled`` simulates it (the same settings, by the same names; docs/coupled.md):
    one string's regime, rate of penetration (m/h), stuck and off-bottom shares, period and the
    ranges of bit speed (rpm), weight (kN) and torque (kN·m), with ``steady`` drilling at its
    drive; with ``record=True`` its samples under ``record`` as columns (what a rig streams,
    ``top_drive_rpm`` and ``surface_torque_knm``, then the bit's channels). With ``map=True`` the
    regime map over ``map_rpm`` × ``map_wob_kn`` (or ``map_feed_m_h`` under a feed): ``cells``,
    speeds down, drives across; with ``escape=True`` too, every cell continues from where the
    bit is at ``omega_rpm`` under its drive, with ``from`` and the way out under ``advice``.
    The bit is held down by ``wob_kn`` or fed at ``feed_m_h`` (30 m/h where neither is
    given)."""
    import json

    options = {k: v for k, v in locals().items() if k not in ("record", "map", "json")}
    return json.loads(_bitrock.coupled(options, record, map, _note))


def coupled_well(path: str | os.PathLike[str], *, record: bool = False) -> dict:
    """One string of the coupled bit drilled through the well file at ``path`` (TOML: the bit,
    the string and ``[[segment]]``s in drilling order, each with its rock, top-drive speed and
    weight or feed; docs/coupled.md), as ``bitrock coupled --well`` drills it: under
    ``segments`` each segment's name, start and duration (s), top-drive speed (rpm), ``drive``
    (``wob_kn`` or ``feed_m_h``), each a number or, where the segment ramps it, ``{"from": …,
    "to": …}``, regime, rate of penetration (m/h), stuck and off-bottom shares and ranges, with
    its ``steady`` drilling (at the ramp's end); with ``record=True`` the samples under
    ``record`` as columns (``top_drive_rpm`` among them), ``segment`` naming each sample's
    segment. A segment spent off bottom nearly throughout is said as a ``BitrockWarning``."""
    import json

    well = json.loads(_bitrock.coupled_well(os.fspath(path), record, _note))
    if record:
        names = [s["name"] for s in well["segments"]]
        well["record"]["segment"] = [names[i] for i in well["record"]["segment"]]
    return well


def coupled_calibrate(
    path: str | os.PathLike[str],
    *,
    speed_col: str | None = None,
    torque_col: str | None = None,
    wob_col: str | None = None,
    rop_col: str | None = None,
    axial_speed_col: str | None = None,
    axial_acceleration_col: str | None = None,
    time_col: str | None = None,
    speed_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    rop_unit: str | None = None,
    acceleration_unit: str | None = None,
    omega_rpm: float | None = None,
    wob_kn: float | None = None,
    feed_m_h: float | None = None,
    radius_m: float | None = None,
    intrinsic_energy_mpa: float | None = None,
    zeta: float | None = None,
    contact_stress_mpa: float | None = None,
    wear_flat_mm: float | None = None,
    friction: float | None = None,
    gamma: float | None = None,
    blades: int | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    mass_kg: float | None = None,
    axial_stiffness_kn_m: float | None = None,
    axial_damping_kns_m: float | None = None,
    duration_s: float | None = None,
    settle_s: float | None = None,
    sample_hz: float | None = None,
    dt_s: float | None = None,
    kick_rpm: float | None = None,
    map_rpm: str | None = None,
    map_wob_kn: str | None = None,
    map_feed_m_h: str | None = None,
    escape: bool | None = None,
    samples: int | None = None,
    seed: int | None = None,
    backend: str | None = None,
    map: bool = False,
) -> dict:
    """The coupled bit calibrated on a drilling record (bit speed, torque on bit, weight on bit,
    rate of penetration; the bit's axial speed or axial acceleration where present; a CSV file),
    as the ``coupled`` command calibrates it: the weight and torque lines through the samples of
    a bit moving down (by its axial speed, by its axial acceleration summed between the bit's
    rests: ``axial_rests``, or without either the upper edge of the weight against the depth of
    cut: ``cutting_by``), ε (MPa), ζ, the wear flats' contact force (kN) and μ·γ with 90 % intervals,
    and a ``warning`` where the record cannot tell a cutting bit from a held one. With
    ``map=True``: ``{"calibration": ..., "map": ...}``, the map giving each regime's probability
    per cell over ``samples`` posterior draws; with ``escape=True`` too, each draw's bit settled
    at ``omega_rpm`` under ``wob_kn`` or ``feed_m_h`` (where the record's bit was drilling: all
    needed) and continued from there, and the way out (``map["advice"]``); ``escape`` without
    ``map=True`` is refused."""
    import json

    columns = {k: v for k, v in locals().items() if k.endswith("_col") or k.endswith("_unit")}
    options = {k: v for k, v in locals().items() if k not in columns and k not in ("path", "map", "columns", "json")}
    return json.loads(_bitrock.coupled_calibrate(os.fspath(path), columns, options, map, _note))


def coupled_select(
    path: str | os.PathLike[str],
    *,
    omega_rpm: float,
    speed_col: str | None = None,
    torque_col: str | None = None,
    wob_col: str | None = None,
    speed_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    wob_kn: float | None = None,
    radius_m: float | None = None,
    contact_stress_mpa: float | None = None,
    gamma: float | None = None,
    blades: int | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    mass_kg: float | None = None,
    axial_stiffness_kn_m: float | None = None,
    axial_damping_kns_m: float | None = None,
    settle_s: float | None = None,
    sample_hz: float | None = None,
    dt_s: float | None = None,
    kick_rpm: float | None = None,
    reference: int | None = None,
    replicates: int | None = None,
    seed: int | None = None,
) -> dict:
    """Which structure a bit record shows (bit speed, torque on bit and weight on bit; a CSV
    file), as ``bitrock coupled --select`` chooses it: every torsional law m1-m4 and the coupled
    bit simulated at the record's drive (``omega_rpm``, the top drive's speed while recorded;
    ``wob_kn``, the record's mean weight on bit where not given; ``sample_hz``, the record's
    rate, 50 Hz by default), ``reference`` candidates of
    each, the structures' probabilities their shares of the candidates nearest the record, and
    the choice checked by ``replicates`` records re-simulated from each. ``decided`` names the
    structure where the check allows it (``None`` otherwise, ``verdict`` saying why), ``family``
    the same choice between the torsional laws together and the coupled bit."""
    import json

    columns = {k: v for k, v in locals().items() if k.endswith("_col") or k.endswith("_unit")}
    options = {k: v for k, v in locals().items() if k not in columns and k not in ("path", "columns", "json")}
    return json.loads(_bitrock.coupled_select(os.fspath(path), columns, options, _note))


def coupled_select_surface(
    path: str | os.PathLike[str],
    *,
    time_col: str | None = None,
    top_drive_col: str | None = None,
    surface_torque_col: str | None = None,
    wob_col: str | None = None,
    top_drive_unit: str | None = None,
    torque_unit: str | None = None,
    wob_unit: str | None = None,
    wob_kn: float | None = None,
    radius_m: float | None = None,
    contact_stress_mpa: float | None = None,
    gamma: float | None = None,
    blades: int | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    mass_kg: float | None = None,
    axial_stiffness_kn_m: float | None = None,
    axial_damping_kns_m: float | None = None,
    settle_s: float | None = None,
    dt_s: float | None = None,
    kick_rpm: float | None = None,
    reference: int | None = None,
    replicates: int | None = None,
    seed: int | None = None,
) -> dict:
    """Which structure a surface record shows (time, top-drive speed, surface torque and, where
    recorded, weight on bit; a CSV file), as ``bitrock coupled --select RECORD --from-surface``
    chooses it: ``coupled_select``'s choice on the surface torque alone, every candidate
    simulated at the record's mean top-drive speed (refused where it is not steady) on the
    record's clock, under ``wob_kn`` or the record's mean weight on bit, each law's candidates
    drawn from ``surface``'s prior of it; ``torque_unit`` is the surface torque's."""
    import json

    columns = {k: v for k, v in locals().items() if k.endswith("_col") or k.endswith("_unit")}
    options = {k: v for k, v in locals().items() if k not in columns and k not in ("path", "columns", "json")}
    return json.loads(_bitrock.coupled_select_surface(os.fspath(path), columns, options, _note))


def simulate_strings(
    law: str,
    *,
    omega_rpm: "float | Sequence[float]",
    wob_kn: "float | Sequence[float]",
    params: "Sequence[float] | Sequence[Sequence[float]] | None" = None,
    param_torque_unit: str | None = None,
    w_ref_kn: float | None = None,
    structure: str | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    fe_file: str | os.PathLike[str] | None = None,
    dp_elements: int | None = None,
    bha_elements: int | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    start: str | None = None,
    kick: float | None = None,
    dt_s: float | None = None,
    settle_s: float | None = None,
    record_s: float | None = None,
    backend: str | None = None,
) -> pd.DataFrame:
    """Drill strings simulated in time, one per top-drive speed ``omega_rpm`` and weight on
    bit ``wob_kn`` (scalars are repeated; ``params`` one set for all, or one row per string,
    torques in ``param_torque_unit``, the paper's estimate by default), as ``bitrock stability
    --simulate`` simulates them: the 1-DOF string or the finite-element string lumped
    (``structure="fe"``), Karnopp stick, RK4 at ``dt_s`` (0.01 s), from steady rotation kicked
    by ``kick`` × Ω (``start="steady"``, a tenth by default) or from rest (``start="rest"``),
    ``settle_s`` (60) then summarised over ``record_s`` (60) at 50 Hz. One row per string:
    ``stuck_share`` (bit below 1 rpm), ``period_s`` (between stick onsets; NaN with fewer than
    two), ``speed_min_rpm``, ``speed_max_rpm``, ``speed_mean_rpm``, ``severity``, bit and surface
    torque extremes in the parameters' torque unit, ``stick_slips`` and ``diverged``, on
    ``backend`` (auto: the GPU where one is usable)."""
    speeds = np.atleast_1d(np.asarray(omega_rpm, dtype=float))
    weights = np.atleast_1d(np.asarray(wob_kn, dtype=float))
    n = max(len(speeds), len(weights))
    if len(speeds) == 1:
        speeds = np.repeat(speeds, n)
    if len(weights) == 1:
        weights = np.repeat(weights, n)
    rows = None
    if params is not None:
        table = np.atleast_2d(np.asarray(params, dtype=float))
        rows = [list(map(float, r)) for r in (np.repeat(table, n, axis=0) if len(table) == 1 else table)]
    options = {
        k: v
        for k, v in locals().items()
        if k not in ("law", "params", "omega_rpm", "wob_kn", "speeds", "weights", "n", "table", "rows")
    }
    if options["fe_file"] is not None:
        options["fe_file"] = os.fspath(options["fe_file"])
    out = _bitrock.simulate_strings(law, rows, [float(v) for v in speeds], [float(v) for v in weights], options, _note)
    unit = out.pop("torque_unit")
    frame = pd.DataFrame({"omega_rpm": speeds, "wob_kn": weights, **out})
    frame.attrs["torque_unit"] = unit
    return frame


def parity(
    record: Record | None = None,
    *,
    laws: str | Sequence[str] | None = None,
    candidates: int | None = None,
    epsilon: float | None = None,
    seed: int | None = None,
) -> dict[str, Any]:
    """Checks this machine's GPU against the f64 CPU reference, as ``bitrock parity`` does:
    the same ``candidates`` per law scored on both (relative differences of ρ against the
    tolerance, decisions at ``epsilon`` that differ away from it), and the candidate generator
    compared bit for bit. Returns the report (``pass``, ``adapter``, ``tolerance``, ``laws``,
    ``philox``). Raises :class:`GpuError` without a usable GPU."""
    return json.loads(
        _bitrock.parity(
            _record(record, optional=True),
            _law_names(laws),
            {"candidates": candidates, "epsilon": epsilon, "seed": seed},
        )
    )


@dataclass(frozen=True)
class Result:
    """A finished ABC run: its populations, model probabilities and particles."""

    _run: Any

    @property
    def document(self) -> dict[str, Any]:
        """The run's ``run.json`` document (configuration, fits, priors, populations,
        posterior summary)."""
        return json.loads(self._run.summary)

    @property
    def path(self) -> pathlib.Path | None:
        """The run directory, or ``None`` for a run in memory."""
        return self._run.path

    @property
    def laws(self) -> list[str]:
        return list(self.document["config"]["laws"])

    @property
    def record(self) -> Record:
        """The record the run was made from, its samples as the run used them (read back from
        the store for a stored run)."""
        return self._run.record()

    @property
    def populations(self) -> pd.DataFrame:
        """One row per population: ε, accepted, drawn, acceptance rate, ESS, whether it is thin
        (ESS below 10 % of its particles), seconds."""
        rows = [
            {
                "population": p["index"],
                "epsilon": np.inf if p["epsilon"] is None else p["epsilon"],
                "accepted": p["accepted"],
                "drawn": p["draws"],
                "acceptance_rate": p["acceptance_rate"],
                "ess": p["ess"],
                "thin": p.get("thin", p["ess"] < _MIN_ESS_SHARE * p["accepted"]),
                "seconds": p["seconds"],
            }
            for p in self.document["populations"]
        ]
        return pd.DataFrame(rows).set_index("population")

    @property
    def traffic(self) -> pd.DataFrame | None:
        """For a run on an executor, one row per population this invocation ran: rounds,
        tasks, bytes of requests, of payloads (record and previous population, once per worker
        that asked) and of replies, and the seconds the driver waited for the workers.
        ``None`` for a run in one process."""
        if self._run.traffic is None:
            return None
        frame = pd.DataFrame(json.loads(self._run.traffic))
        return frame.set_index("population") if len(frame) else frame

    @property
    def _label(self) -> str:
        """What the run's model probabilities are (a run.json written without it: the paper's
        ABC's, as every run's)."""
        return self.document["posterior"].get("label", "the paper's ABC, P(m | ρ < ε)")

    @property
    def answer(self) -> dict[str, Any] | None:
        """The run's answer to "which law, how sure": ``law`` and ``probability``, the
        ``runner_up`` and its probability, ``ln_b`` ± ``error`` between them, ``strength``
        (``undecided``, ``decided_by_the_boxes``, ``positive``, ``strong``, ``very_strong``;
        never stronger than what the record separates), ``why`` and the ``sentence`` the command
        prints. The paper's ABC's probabilities far above the record's likelihood scale are
        ratios of prior volumes: their answer is decided by the boxes (see
        :func:`evidence` for the model evidence). ``None`` where no law holds a particle."""
        return self.document.get("answer")

    @property
    def model_probabilities(self) -> pd.DataFrame:
        """Population × law model probabilities by the paper's ABC, P(m | ρ < ε): the share
        of each law's prior box below each population's ε (also a column). They weigh the
        record only where ε lies near its likelihood scale (:attr:`answer`, and the run's
        warning where it does not); ``frame.attrs["label"]`` says what they are."""
        doc = self.document
        laws = doc["config"]["laws"]
        rows = []
        for p in doc["populations"]:
            row = {law: p["model_probabilities"].get(law, 0.0) for law in laws}
            row["epsilon"] = np.inf if p["epsilon"] is None else p["epsilon"]
            rows.append(row)
        frame = pd.DataFrame(rows, columns=[*laws, "epsilon"])
        frame.index.name = "population"
        frame.attrs["label"] = self._label
        return frame

    def _population(self, population: int) -> int:
        count = len(self.document["populations"])
        g = population + count if population < 0 else population
        if not 0 <= g < count:
            raise InputError(f"population: the run has populations 0..={count - 1}, got {population}", "population")
        return g

    def particles(self, population: int = -1) -> dict[str, tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Population ``population``'s particles by law: ``(names, params [n, k] in the
        record's torque unit, weights, rho, candidate index)``."""
        return self._run.particles(self._population(population))

    def predictive(
        self,
        speed_rad_s: "Sequence[float] | np.ndarray",
        *,
        level: float = 0.98,
        population: int = -1,
        r: float = 1.0,
    ) -> Any:
        """The posterior predictive band of each law with particles in ``population`` (the last
        by default) at the bit speeds ``speed_rad_s`` (rad/s) and weight-on-bit ratio ``r``: an
        ``xarray.Dataset`` over ``law`` × ``speed_rad_s`` with ``lower``, ``median`` and
        ``upper``, the pointwise (1 ∓ ``level``)/2 quantiles and median of the particles'
        torques (weighted), in the record's torque unit; the run's ``envelopes.csv`` at
        ``level`` 0.98."""
        import xarray as xr

        speeds = np.asarray(speed_rad_s, dtype=float).ravel()
        bands = self._run.predictive(self._population(population), [float(w) for w in speeds], float(level), float(r))
        laws = list(bands)
        unit = self.document["data"]["torque_unit"]
        variables = {
            name: (("law", "speed_rad_s"), np.stack([bands[law][i] for law in laws]) if laws else np.zeros((0, len(speeds))), {"units": unit})
            for i, name in enumerate(("lower", "median", "upper"))
        }
        return xr.Dataset(
            variables,
            coords={"law": laws, "speed_rad_s": ("speed_rad_s", speeds, {"units": "rad/s"})},
            attrs={"level": level, "wob_ratio": r},
        )

    def history(self) -> Any:
        """The run as pyABC's ``History`` reads (a read-only view): pyABC's
        ``plot_model_probabilities``, ``plot_epsilons``, ``plot_credible_intervals``,
        ``plot_effective_sample_sizes`` and ``plot_kde_*`` take it. Models are numbered 0, 1, …
        in the order of :attr:`laws`."""
        from ._history import History

        return History(self)

    def save(self, path: str | os.PathLike[str], *, force: bool = False) -> "Result":
        """Writes a run kept in memory to the run directory ``path`` (``force`` replaces a run
        there) as :func:`abc` with ``out=path`` would have written it: the same store, run.json,
        envelopes and data, so that ``bitrock export``, ``report``, ``stability``,
        :func:`check_selection` and :func:`resume` read it. Returns the stored run."""
        if self.path is not None:
            raise InputError(f"path: the run is stored already, in {self.path}", "path")
        return Result(self._run.save(os.fspath(path), force))

    def get_distribution(self, law: str, population: int = -1) -> tuple[pd.DataFrame, np.ndarray]:
        """The law's particles in ``population`` (the last by default) and their weights,
        normalised within the law: ``(DataFrame of parameters, weights)``, as pyABC's
        ``History.get_distribution(m, t)`` returns them, so that its plotting functions
        accept them."""
        if law not in self.laws:
            raise InputError(f"law: the run's laws are {', '.join(self.laws)}, got {law!r}", "law")
        found = self.particles(population).get(law)
        if found is None:
            names = _param_names(self.document, law)
            return pd.DataFrame(columns=names, dtype=float), np.zeros(0)
        names, params, weights, _rho, _index = found
        frame = pd.DataFrame(params, columns=names)
        frame.columns.name = "name"
        total = weights.sum()
        return frame, weights / total if total > 0 else weights

    def summary(self) -> pd.DataFrame:
        """The summarised population's posterior per law and parameter: probability (the
        paper's ABC's, P(m | ρ < ε), as ``frame.attrs["label"]`` says), mean,
        standard deviation, 1 %, 50 % and 99 % quantiles, MAP, in the record's torque unit, and
        ``identified``: false where the record has not narrowed the prior box (its central 98 %
        still spans over 76 % of the box), so that the box, not the data, sets those numbers."""
        rows = []
        for s in self.document["posterior"]["laws"]:
            for i, name in enumerate(s["names"]):
                rows.append(
                    {
                        "law": s["law"],
                        "parameter": name,
                        "unit": s["units"][i],
                        "probability": s["probability"],
                        "mean": s["mean"][i],
                        "std_dev": s["std_dev"][i],
                        "q01": s["q01"][i],
                        "q50": s["q50"][i],
                        "q99": s["q99"][i],
                        "map": s["map"][i],
                        # A run.json written without the marks counts every parameter identified.
                        "identified": s.get("identified", [True] * len(s["names"]))[i],
                    }
                )
        frame = pd.DataFrame(rows)
        frame.attrs["label"] = self._label
        return frame

    def to_datatree(self, population: int = -1, *, resample: bool | int = False) -> Any:
        """The population (the last by default) as an ``xarray.DataTree``: one node per law
        with the groups ArviZ reads, ``posterior`` (each parameter over ``chain`` × ``draw``,
        one chain, in the record's torque unit) and ``sample_stats`` (``weight``, normalised
        within the law, and the misfit ``rho``), and at the root ``model_probabilities``
        (population × law, with ``epsilon``). ABC particles carry weights (uniform for the
        rejection sampler, not for SMC): estimates that ignore ``weight`` treat them as equal.
        ``resample=True`` (or a count of draws) replaces each law's particles by an
        equal-weight systematic resample of them (as many draws as particles, or the count;
        deterministic), so that ArviZ's summaries, which treat draws as equal, are those of the
        weighted posterior. ArviZ 1.x reads a law's node directly (``tree["m2"]``); ArviZ 0.23
        through ``arviz.InferenceData.from_datatree(tree["m2"])``."""
        import xarray as xr

        g = self._population(population)
        doc = self.document
        probabilities = self.model_probabilities
        nodes: dict[str, xr.Dataset] = {
            "/": xr.Dataset(
                {
                    "model_probabilities": (("population", "law"), probabilities[self.laws].to_numpy()),
                    "epsilon": ("population", probabilities["epsilon"].to_numpy()),
                },
                coords={"population": probabilities.index.to_numpy(), "law": self.laws},
                attrs={"source": doc["data"]["source"], "population": g, "torque_unit": doc["data"]["torque_unit"]},
            )
        }
        particles = self.particles(g)
        for law in self.laws:
            names, params, weights, rho, _index = particles.get(
                law, (_param_names(doc, law), np.zeros((0, len(_param_names(doc, law)))), np.zeros(0), np.zeros(0), None)
            )
            units = dict(zip(_param_names(doc, law), _param_units(doc, law)))
            if resample is not False and len(weights):
                count = len(weights) if resample is True else _positive_count(resample, "resample")
                chosen = _systematic_resample(weights, count)
                params, rho, weights = params[chosen], rho[chosen], np.ones(count)
            draws = np.arange(len(weights))
            nodes[f"/{law}/posterior"] = xr.Dataset(
                {n: (("chain", "draw"), params[None, :, i], {"units": units.get(n, "")}) for i, n in enumerate(names)},
                coords={"chain": [0], "draw": draws},
                attrs={"law": law, "population": g, "inference_library": "bitrock", "inference_library_version": __version__},
            )
            total = weights.sum()
            nodes[f"/{law}/sample_stats"] = xr.Dataset(
                {
                    "weight": (("chain", "draw"), (weights / total if total > 0 else weights)[None, :]),
                    "rho": (("chain", "draw"), rho[None, :]),
                },
                coords={"chain": [0], "draw": draws},
            )
        return xr.DataTree.from_dict(nodes)

    def __repr__(self) -> str:
        doc = self.document
        probabilities = ", ".join(f"{k} {v:.3f}" for k, v in doc["posterior"]["model_probabilities"].items())
        where = self.path or "in memory"
        answer = self.answer
        strength = f"; first {answer['law']} ({answer['strength'].replace('_', ' ')})" if answer else ""
        return f"<bitrock.Result {len(doc['populations'])} populations ({where}); P(m | ρ < ε): {probabilities}{strength}>"

    def _repr_html_(self) -> str:
        """A notebook's view: where the run lives, the model probabilities of every population
        with its ε, and the run's warnings."""
        import html

        doc = self.document
        where = html.escape(str(self.path)) if self.path is not None else "in memory"
        table = self.model_probabilities.to_html(float_format=lambda v: f"{v:.4f}")
        warnings = "".join(f"<li>warning: {html.escape(w)}</li>" for w in doc.get("warnings", []))
        answer = self.answer
        return (
            f"<div><b>bitrock.Result</b>: {len(doc['populations'])} populations ({where}), "
            f"model probabilities by {html.escape(self._label)}, by population{table}"
            + (f"<p><b>answer</b>: {html.escape(answer['sentence'])}</p>" if answer else "")
            + (f"<ul>{warnings}</ul>" if warnings else "")
            + "</div>"
        )


def _systematic_resample(weights: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` equal-weight draws from particles of ``weights``: systematic
    resampling at the offsets (i + ½) / count, so each particle is drawn ⌊count·w⌋ or
    ⌈count·w⌉ times, and the same weights always give the same draws."""
    cumulative = np.cumsum(weights / weights.sum())
    cumulative[-1] = 1.0
    return np.searchsorted(cumulative, (np.arange(count) + 0.5) / count, side="right")


def _positive_count(value: Any, argument: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{argument}: give True or a number of draws (at least 1), got {value!r}", argument)
    return int(value)


def _param_names(doc: dict[str, Any], law: str) -> list[str]:
    for f in doc["fits"]:
        if f["law"] == law:
            return list(f["names"])
    return []


def _param_units(doc: dict[str, Any], law: str) -> list[str]:
    for f in doc["fits"]:
        if f["law"] == law:
            return list(f["units"])
    return []
