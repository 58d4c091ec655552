"""Progress bars for long jobs (synth, track, replay): tqdm on standard error.

On a terminal the bar redraws in place; in a log (CI, docker) tqdm prints at most one line
every ``mininterval`` seconds. ``enabled=False`` (``--quiet`` / ``-q``) shows nothing.
"""

from __future__ import annotations

import sys

from tqdm import tqdm

LOG_INTERVAL_S = 10.0
"""Seconds between progress lines when standard error is not a terminal."""


def progress_bar(label: str, total: int | None, enabled: bool = True, unit: str = "frame") -> tqdm:
    """A bar of ``total`` items (None: unknown) of ``unit`` labelled ``label``; call ``update(n)`` and ``close()``."""
    tty = bool(getattr(sys.stderr, "isatty", lambda: False)())
    return tqdm(total=total or None, desc=label, unit=unit, disable=not enabled, file=sys.stderr,
                mininterval=0.1 if tty else LOG_INTERVAL_S, dynamic_ncols=tty, leave=True)
