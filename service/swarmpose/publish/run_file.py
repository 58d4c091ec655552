"""``run.json``: what a run with ``--out`` (or ``--record``) was made with, beside its poses: the
source, the 2D detector it asked for and the one that ran with its model file, the body, the
coordinates and every tracker setting. Written once, when the outputs are opened."""

from __future__ import annotations

import json
from pathlib import Path

from swarmpose.core.errors import OutputError

RUN_FILE = "run.json"


def write_run_file(out_dir: str | Path, record: dict) -> Path:
    """Write ``record`` (JSON-ready) as ``out_dir/run.json`` with its ``schema``; OutputError naming
    the file when it cannot be written."""
    path = Path(out_dir) / RUN_FILE
    try:
        path.write_text(json.dumps({"schema": "swarmpose.run", "version": 1, **record}, indent=1) + "\n",
                        encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}; choose a writable output folder") from exc
    return path
