"""Exceptions of bitrock. Plain Python classes, so that they survive pickling back from a
worker process."""

from __future__ import annotations

import errno as _errno
import os as _os


class BitrockError(Exception):
    """A failure of bitrock's computation or of the machine (a full disk, a GPU lost)."""


class InputError(BitrockError, ValueError):
    """Bad input: an argument out of range, a malformed record. ``argument`` names the
    keyword argument at fault (``particles``), or is ``None`` when a file is (its path, line
    and column are in the message)."""

    def __init__(self, message: str, argument: str | None = None) -> None:
        super().__init__(message, argument)
        self.message = message
        self.argument = argument

    def __str__(self) -> str:
        return self.message


class GpuError(BitrockError):
    """The GPU could not be used (no adapter, out of memory, a lost device)."""


class BitrockWarning(UserWarning):
    """What a run says once without failing: a fallback to the CPU, a tolerance floor moved to
    the record's reach, a run continued from its store. Silence them with
    ``warnings.filterwarnings("ignore", category=bitrock.BitrockWarning)``."""


def os_error(code: int, message: str, path: str) -> OSError:
    """The ``OSError`` subclass Python raises for ``code`` (``FileNotFoundError`` for ENOENT),
    with bitrock's message and the path."""
    return OSError(code or _errno.EIO, message, _os.fspath(path))
