"""
The extension module: the Rust library's entry points. Use the ``bitrock`` package, which
wraps these in pandas and xarray; signatures here may change between releases.
"""

from _typeshed import Incomplete, SupportsGetItem
from os import PathLike
from pathlib import Path
from typing import Any, SupportsFloat, SupportsIndex, final

__all__ = ["ComputedEvidence", "Record", "Run", "abc", "check_selection", "check_surface", "coupled", "coupled_calibrate", "coupled_select", "coupled_select_surface", "coupled_well", "evidence", "fit", "is_evidence_dir", "is_information", "is_surface_dir", "law_colours", "load_law", "needs_payloads", "open_run", "parity", "read_columns", "read_csv", "read_evidence", "read_surface", "read_watch", "resume", "resume_evidence", "resume_surface", "serve", "settings_fields", "simulate", "simulate_strings", "stability", "surface", "torque", "version", "watch"]

@final
class ComputedEvidence:
    """
    An evidence computed in this process: its document (`bitrock evidence --json`'s, each law's
    posterior sets added) and what writing it as an evidence directory needs.
    """
    def __reduce__(self, /) -> tuple[Any, tuple[str]]:
        """
        Pickling: the document, the posterior's CSV, the job and the record, as JSON exact to
        the bit; rebuilt by [`ComputedEvidence::_from_state`].
        """
    @staticmethod
    def _from_state(state: str) -> ComputedEvidence:
        """
        The evidence a pickle's state describes.
        """
    @property
    def document(self, /) -> str:
        """
        The evidence's document, as JSON.
        """
    def save(self, /, path: str | PathLike[str], force: bool) -> None:
        """
        Writes the evidence as the evidence directory `path` (`force` replaces an evidence
        there), as `bitrock evidence --out` writes one.
        """

@final
class Record:
    """
    A field record, read and split into calibration and validation samples (SI inside).
    """
    def __reduce__(self, /) -> tuple[Any, tuple[str]]:
        """
        Pickling: the record whole (samples, units, columns, warnings) as JSON, exact to the
        bit (shortest round-trip decimals), rebuilt by [`Record::_from_state`].
        """
    def __repr__(self, /) -> str: ...
    @staticmethod
    def _from_state(state: str) -> Record:
        """
        The record a pickle's state describes.
        """
    def _repr_html_(self, /) -> str:
        """
        A notebook's view: where the record came from, what was used, in which units, the
        speed and torque ranges of the calibration samples, and the warnings.
        """
    def calibration(self, /) -> tuple[Incomplete, Incomplete]:
        """
        The calibration samples: bit speed (rad/s) and torque (N·m), without copies.
        """
    @property
    def columns(self, /) -> tuple[str, str, str | None, str | None]:
        """
        `{"speed", "torque", "wob", "time"}`: the columns read.
        """
    @property
    def rows_read(self, /) -> int: ...
    @property
    def rows_used(self, /) -> int: ...
    @property
    def source(self, /) -> str:
        """
        Where the record came from.
        """
    @property
    def speed_unit(self, /) -> str: ...
    @property
    def torque_unit(self, /) -> str:
        """
        The unit torques are given and reported in (`kN·m`, `N·m`).
        """
    def validation(self, /) -> tuple[Incomplete, Incomplete]:
        """
        The validation samples: bit speed (rad/s) and torque (N·m).
        """
    @property
    def warnings(self, /) -> list[str]: ...

@final
class Run:
    """
    A finished run: its `run.json` document, and the particles of any population.
    """
    def __reduce__(self, /) -> tuple[Any, tuple[str]]:
        """
        Pickling: the document, the directory, and a run in memory's populations with their
        particles, as JSON exact to the bit; rebuilt by [`Run::_from_state`].
        """
    @staticmethod
    def _from_state(state: str) -> Run:
        """
        The run a pickle's state describes.
        """
    def particles(self, /, g: SupportsIndex) -> dict:
        """
        The particles of population `g` by law: `{law: (params [n, k] in the record's torque
        unit, weights, rho, candidate index)}`.
        """
    @property
    def path(self, /) -> Path | None:
        """
        The run directory; `None` for a run in memory.
        """
    def predictive(self, /, g: SupportsIndex, speed_rad_s: SupportsGetItem[int, SupportsFloat | SupportsIndex], level: SupportsFloat | SupportsIndex, r: SupportsFloat | SupportsIndex) -> dict:
        """
        The `level` posterior predictive band of every law with particles in population `g` at
        the bit speeds `speed_rad_s` and weight-on-bit ratio `r`: `{law: (lower, median,
        upper)}` in the record's torque unit, pointwise quantiles as the run's envelopes.
        """
    def record(self, /) -> Record:
        """
        The record the run was made from (its calibration and validation samples as the run
        used them).
        """
    def save(self, /, path: str | PathLike[str], force: bool) -> Run:
        """
        Writes a run kept in memory to the run directory `path` (`force` replaces a run
        there), as `bitrock abc --out` would have written it, and returns the stored run.
        """
    @property
    def summary(self, /) -> str:
        """
        The run.json document.
        """
    @property
    def traffic(self, /) -> str | None:
        """
        Per population of a distributed run: tasks, bytes shipped, seconds waited (JSON).
        """

def abc(record: Record, settings: dict, out: str | PathLike[str] | None, force: bool, progress: Any | None, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> Run:
    """
    Runs the ABC job on `record` with the settings in `settings` (keyword arguments of
    `bitrock.abc`), into `out` when given.
    """

def check_selection(run: str | PathLike[str] | None, in_memory: Run | None, options: dict, progress: Any | None, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> str:
    """
    Checks the selection of the run in directory `run` by re-simulation, writes it into the
    run's `selection/` (as `bitrock check-selection` does) and returns its document; a run kept
    in memory (`in_memory`, `run` then `None`) is checked alike and its document only returned.
    An evidence directory's evidence is computed again and checked, the check written into its
    document and returned; with a `dispatcher` (`bitrock._distributed.Dispatcher`) its
    candidates are scored by the dispatcher's workers, `parallelism` tasks a batch.
    """

def check_surface(dir: str | PathLike[str], replicates: SupportsIndex | None, backend: str | None, note: Any | None) -> str:
    """
    `bitrock check-selection` on the surface directory `dir`: its check made again with
    `replicates` records per law (default: the command's), on `backend` (default: the run's),
    the directory written anew; the whole result as JSON text.
    """

def coupled(options: dict, record: bool, map: bool, note: Any | None) -> str:
    """
    `bitrock coupled` with the settings in `options`: one string (its summary and steady
    drilling, and with `record` its samples as columns), or with `map` the regime map (the
    escape map with the `escape` setting); as JSON text.
    """

def coupled_calibrate(path: str | PathLike[str], columns: dict, options: dict, map: bool, note: Any | None) -> str:
    """
    The bit calibrated on the drilling record at `path` (columns and units in `columns`), and
    with `map` the regimes' probabilities over its posterior (with the `escape` setting, each
    draw's bit continued from where it is at the start, and the way out); as JSON text.
    """

def coupled_select(path: str | PathLike[str], columns: dict, options: dict, note: Any | None) -> str:
    """
    The structure the bit record at `path` shows (columns and units in `columns`): a torsional
    law or the coupled bit, chosen by simulation and checked by re-simulation
    (`bitrock::run::choice`); as JSON text.
    """

def coupled_select_surface(path: str | PathLike[str], columns: dict, options: dict, note: Any | None) -> str:
    """
    The structure the surface record at `path` shows (columns and units in `columns`), from
    its surface torque at its steady top-drive speed (`bitrock::run::choice::surface_choice`);
    as JSON text.
    """

def coupled_well(path: str | PathLike[str], record: bool, note: Any | None) -> str:
    """
    One string drilled through the well file at `path` (`bitrock coupled --well`): each
    segment's report, and with `record` the samples as columns (`segment` each sample's
    segment's index); as JSON text. `note` hears a segment spent off bottom.
    """

def evidence(record: Record, laws: SupportsGetItem[int, str] | None, options: dict, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> ComputedEvidence:
    """
    The evidence of `laws` (`None`: all four) on the record, with the options of
    `bitrock.evidence`: `bitrock evidence --json`'s document, with each law's posterior sets
    (`"posterior": {"params": [[...]], "weights": [...], "island": [...]}`, the record's torque
    unit) added, kept whole so that it can be saved as an evidence directory later. With
    a `dispatcher` (`bitrock._distributed.Dispatcher`), the samplers' candidates are scored by
    its workers, `parallelism` tasks a batch unless it says otherwise.
    """

def fit(record: Record, laws: SupportsGetItem[int, str] | None, options: dict) -> str:
    """
    Least-squares fits of `laws` (`None`: all) to the record: `fit --json`'s document.
    """

def is_evidence_dir(dir: str | PathLike[str]) -> bool:
    """
    True when `dir` is an evidence directory.
    """

def is_information(note: str) -> bool:
    """
    True for a note that only informs (which GPU scores): logged, not warned.
    """

def is_surface_dir(dir: str | PathLike[str]) -> bool:
    """
    True when `dir` holds a surface run (`bitrock surface --out`).
    """

def law_colours(laws: SupportsGetItem[int, str]) -> list[str]:
    """
    Each law's colour (`#rrggbb`) by its name, the same in every figure of the report, on the
    watch's page and in `bitrock.plot`.
    """

def load_law(path: str | PathLike[str]) -> str:
    """
    Reads, compiles and registers the law file at `path`; its law's name, for `laws=` and
    `law=` everywhere in this process.
    """

def needs_payloads(reply: bytes) -> bool:
    """
    True when a worker's reply asks for the problem and context payloads.
    """

def open_run(path: str | PathLike[str]) -> Run:
    """
    Opens the finished run in `path`: its run.json and its store.
    """

def parity(record: Record | None, laws: SupportsGetItem[int, str] | None, options: dict) -> str:
    """
    CPU-vs-GPU parity on `record` (`None`: the embedded demo record): `bitrock parity`'s
    report as JSON text.
    """

def read_columns(names: SupportsGetItem[int, str], columns: SupportsGetItem[int, Incomplete | None], source: str, options: dict) -> Record:
    """
    Reads a record from named float64 columns (a DataFrame's), read without copies; `None`
    for a column that holds no numbers.
    """

def read_csv(path: str | PathLike[str] | None, options: dict) -> Record:
    """
    Reads a CSV record at `path` (`None`: the embedded demo record).
    """

def read_evidence(dir: str | PathLike[str]) -> str:
    """
    The document of the evidence directory `dir` (`bitrock evidence --out`, `bitrock.evidence(...,
    out=...)`), as JSON.
    """

def read_surface(dir: str | PathLike[str]) -> str:
    """
    The finished surface run in `dir`: its document with the record's clock, as JSON text.
    """

def read_watch(dir: str | PathLike[str]) -> tuple[str, list[str]]:
    """
    The watch stored in `dir` (written by `bitrock watch --out` or `bitrock.watch(out=...)`):
    its description and every window's update, as JSON.
    """

def resume(path: str | PathLike[str], more: dict, progress: Any | None, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> Run:
    """
    Continues the run in `path` with the stopping rules in `more`.
    """

def resume_evidence(dir: str | PathLike[str], backend: str | None, check: SupportsIndex | None, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> ComputedEvidence:
    """
    Continues the evidence under way in `dir` (on `backend`, default its own), checks it with
    `check` replicates per law (by default the small check; 0 none), and writes the directory:
    the document, as [`evidence`] returns it.
    """

def resume_surface(dir: str | PathLike[str], max_populations: SupportsIndex | None, max_seconds: SupportsFloat | SupportsIndex | None, backend: str | None, check_replicates: SupportsIndex | None, note: Any | None, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> str:
    """
    `bitrock surface --resume`: the surface run in `dir` continued with `more`'s stopping rules
    and backend, the directory written anew, on the workers of `dispatcher` where given; the
    whole result as JSON text.
    """

def serve(request: bytes, problem: bytes | None = None, context: bytes | None = None) -> bytes:
    """
    Answers a task on a worker process (see `bitrock::abc::shard::wire`).
    """

def settings_fields(kind: str) -> list[str]:
    """
    The fields of a kind of run's settings (`abc`, `evidence`, `coupled`, `surface`): the keyword arguments its Python
    function must take, as the command takes their flags.
    """

def simulate(law: str, params: SupportsGetItem[int, SupportsFloat | SupportsIndex] | None, omega_rpm: SupportsFloat | SupportsIndex, options: dict, note: Any | None) -> str:
    """
    Simulates the 1-DOF string with `law` at top-drive speed `omega_rpm`: the record as
    `bitrock simulate` writes it (CSV text, torques in kN·m, the `channels` asked for). Parameters that look like the
    wrong torque unit are said through `note`.
    """

def simulate_strings(law: str, params: SupportsGetItem[int, SupportsGetItem[int, SupportsFloat | SupportsIndex]] | None, omega_rpm: SupportsGetItem[int, SupportsFloat | SupportsIndex], wob_kn: SupportsGetItem[int, SupportsFloat | SupportsIndex], options: dict, note: Any | None) -> dict:
    """
    Strings of `law`, one per row of `params` (torques in `param_torque_unit`; `None`: the
    law's reference values for every string), `omega_rpm` and `wob_kn` (equal lengths), started
    from steady rotation kicked by `kick` × Ω or from rest, integrated for `settle_s` then
    summarised over `record_s` at 50 Hz: a dict of NumPy arrays.
    """

def stability(run: str | PathLike[str] | None, law: str | None, params: SupportsGetItem[int, SupportsFloat | SupportsIndex] | None, options: dict, note: Any | None) -> dict:
    """
    Stability maps over (Ω, W) for the run in `run`, or for `law` at `params` (torques in
    `torque_unit`): a dict of NumPy arrays the Python layer makes a Dataset of.
    """

def surface(path: str | PathLike[str], laws: SupportsGetItem[int, str] | None, options: dict, note: Any | None, out: str | PathLike[str] | None = None, force: bool = False, dispatcher: Any | None = None, parallelism: SupportsIndex = 1) -> str:
    """
    `bitrock surface` on the record at `path`: the whole result as JSON text, written as a
    surface directory to `out` where given, its sampler's strings simulated by the workers of
    `dispatcher` where given (the result then carries their `traffic`). The notes of the run
    (a GPU fallback of the advice's strings, say) go to `note` once it is done.
    """

def torque(law: str, speed_rad_s: Incomplete, params: SupportsGetItem[int, SupportsFloat | SupportsIndex], r: SupportsFloat | SupportsIndex, torque_unit: str | None) -> Incomplete:
    """
    The law's torque r·T(w) at the bit speeds `speed_rad_s` (rad/s, a contiguous float64
    array, read without a copy), its parameters `params` in its order with torques in
    `torque_unit` (kN·m by default); the torques in that unit, as a new array. A speed where the
    torque has no value gives NaN.
    """

def version() -> str:
    """
    The library's version.
    """

def watch(source: str | PathLike[str], options: dict, on_update: Any, note: Any | None, stopped: Any | None = None) -> str:
    """
    Follows `source` (a CSV path, or `-` for standard input; `follow`, `replay_speed` as the
    command's flags) with the settings in `options` (`bitrock.watch`'s keyword arguments),
    calling `on_update(json)` with each window's JSON line; an exception raised by it (or
    Ctrl-C) stops the watch and is raised again. `stopped()`, asked between rows, ends the
    watch after the window in progress when true. Returns how the watch ended, as JSON.
    """
