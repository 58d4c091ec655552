"""The common part of the file sinks: one file opened at construction, flushed per frame,
closed once; a write that fails raises :class:`~swarmpose.core.errors.OutputError` naming it."""

from __future__ import annotations

from pathlib import Path
from typing import IO

from swarmpose.core.errors import OutputError


def write_error(what: str, path: Path, exc: BaseException) -> OutputError:
    """The OutputError of ``what`` at ``path`` failing with ``exc``, saying what to do."""
    reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return OutputError(f"cannot write {what} {path}: {reason}; choose a writable output folder with free space")


class ClosingSink:
    """What the sinks that write one output (``self._file``: anything with ``close()``) share: status
    messages are not recorded, and the output is closed once, a failure raising OutputError."""

    what = "file"
    close_errors: tuple[type[BaseException], ...] = (OSError,)
    """What closing the output may raise that means it could not be written."""
    path: Path
    _closed: bool

    def status(self, message: dict) -> None:
        """Status messages are not recorded."""

    def close(self) -> None:
        """Flush and close the output (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._file.close()
        except self.close_errors as exc:
            raise write_error(self.what, self.path, exc) from exc


class FileSink(ClosingSink):
    """A sink writing one file: opened at construction, flushed per frame, closed once."""

    def __init__(self, path: str | Path, mode: str, **kwargs) -> None:
        self.path = Path(path)
        self.frames = 0
        self._closed = False
        try:
            self._file: IO = open(self.path, mode, **kwargs)  # held open until close()
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc

    def _check_open(self) -> None:
        if self._closed:
            raise OutputError(f"{self.what} {self.path} is closed; open a new sink to write more frames")

    def _flush(self) -> None:
        try:
            self._file.flush()
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
