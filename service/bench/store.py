"""The per-run records of the resumable benchmarks (``bench accuracy``, ``bench utdmhad``): one
JSON file per run, written whole or not at all, and read back only when it was made with the
same settings."""

from __future__ import annotations

import json
import os
from pathlib import Path

TRACKER_DEFAULTS = {"particles": 64, "generations": 64, "max_people": 1, "arm_prior": 0.0}
"""The tracker settings every record stores, so that a resume compares them even when the
caller left them at their defaults; a record made before a setting existed reads as its default."""


def tracker_settings(tracker: dict | None) -> dict:
    """``tracker`` with :data:`TRACKER_DEFAULTS` filled in."""
    return {**TRACKER_DEFAULTS, **(tracker or {})}


def read_record(path: Path, expected: dict) -> dict | None:
    """The JSON record at ``path`` if each key of ``expected`` holds the same value in it (a
    tracker setting it lacks: :data:`TRACKER_DEFAULTS`' value); None when it is absent,
    unreadable or was made with other settings."""
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return record if all(record.get(k, TRACKER_DEFAULTS.get(k)) == v for k, v in expected.items()) else None


def write_record(path: Path, record: dict) -> None:
    """Write ``record`` as JSON at ``path`` through a temporary file, so an interrupted run leaves
    the old file or the new one, never half of one."""
    tmp = Path(path).with_suffix(".tmp")
    tmp.write_text(json.dumps(record))
    os.replace(tmp, path)
