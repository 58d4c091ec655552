"""A minimal progress line for long jobs, on standard error."""

from __future__ import annotations

import sys
import time


class Progress:
    """Reports ``label i/total`` on stderr: in place on a terminal, every 10 % otherwise."""

    def __init__(self, label: str, total: int, enabled: bool = True, stream=None):
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start = time.monotonic()
        self._last_decile = -1

    def update(self, done: int) -> None:
        """Report that ``done`` of ``total`` items are finished."""
        if not self.enabled:
            return
        rate = done / max(time.monotonic() - self._start, 1e-9)
        line = f"{self.label}: {done}/{self.total} ({rate:.1f}/s)"
        if self.tty:
            self.stream.write("\r" + line + ("\n" if done >= self.total else ""))
            self.stream.flush()
        else:
            decile = 10 * done // self.total
            if decile != self._last_decile:
                self._last_decile = decile
                self.stream.write(line + "\n")
                self.stream.flush()
