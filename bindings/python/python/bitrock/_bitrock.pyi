"""The extension module: the Rust library's entry points. Use the ``bitrock`` package, which
wraps these in pandas and xarray; signatures here may change between releases."""

from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

class Record:
    """A field record, read and split into calibration and validation samples (SI inside)."""

    @property
    def source(self) -> str: ...
    @property
    def rows_read(self) -> int: ...
    @property
    def rows_used(self) -> int: ...
    @property
    def torque_unit(self) -> str: ...
    @property
    def speed_unit(self) -> str: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def columns(self) -> tuple[str, str, str | None, str | None]:
        """(speed, torque, weight on bit, time): the columns read."""
    def calibration(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Bit speed (rad/s) and torque on bit (N·m) of the calibration samples."""
    def validation(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Bit speed (rad/s) and torque on bit (N·m) of the validation samples."""

Particles = tuple[list[str], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.uint64]]

class Run:
    """A finished run: its run.json document and its particles."""

    @property
    def summary(self) -> str:
        """The run.json document, as text."""
    @property
    def path(self) -> Path | None: ...
    @property
    def traffic(self) -> str | None:
        """Per population of a run on workers: tasks, bytes shipped, seconds waited (JSON)."""
    def particles(self, g: int) -> dict[str, Particles]:
        """Population g's particles by law: (names, params [n, k] in the record's torque unit,
        weights, rho, candidate index)."""

Progress = Callable[[int, int, int, int, float | None], Any]

def read_csv(path: str | PathLike[str] | None, options: dict[str, Any]) -> Record: ...
def read_columns(
    names: list[str], columns: list[npt.NDArray[np.float64] | None], source: str, options: dict[str, Any]
) -> Record: ...
def fit(record: Record, laws: list[str] | None, options: dict[str, Any]) -> str: ...
def abc(
    record: Record,
    settings: dict[str, Any],
    out: str | PathLike[str] | None,
    force: bool,
    progress: Progress | None,
    note: Callable[[str], Any] | None,
    dispatcher: Any = None,
    parallelism: int = 1,
) -> Run: ...
def resume(
    path: str | PathLike[str],
    more: dict[str, Any],
    progress: Progress | None,
    note: Callable[[str], Any] | None,
    dispatcher: Any = None,
    parallelism: int = 1,
) -> Run: ...
def open_run(path: str | PathLike[str]) -> Run: ...
def stability(
    run: str | PathLike[str] | None,
    law: str | None,
    params: list[float] | None,
    options: dict[str, Any],
    note: Callable[[str], Any] | None,
) -> dict[str, Any]:
    """Boundaries and probability grids as NumPy arrays (law × Ω × W)."""
def check_selection(
    run: str | PathLike[str],
    options: dict[str, Any],
    progress: Callable[[int, int], Any] | None,
    note: Callable[[str], Any] | None,
) -> str:
    """The selection check's document, as text."""
def simulate(law: str, params: list[float] | None, omega_rpm: float, options: dict[str, Any]) -> str:
    """The simulated record as CSV text."""
def parity(record: Record | None, laws: list[str] | None, options: dict[str, Any]) -> str:
    """The parity report as JSON text."""
def version() -> str: ...
def serve(request: bytes, problem: bytes | None = None, context: bytes | None = None) -> bytes:
    """Answers one task on a worker process."""
def needs_payloads(reply: bytes) -> bool:
    """True when a worker's reply asks for the record and previous population."""
