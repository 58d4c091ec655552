"""A rerun recording made afterwards from a run's files (``swarmpose view``).

A *recording* is what ``replay``, ``track --out`` or ``serve --record`` leave in a folder:
``poses.jsonl``, one frame message per line. The frames (depth, colour, intrinsics) are not
in it; they come from the source the run tracked (``source``: a sequence folder or any
source URI), matched by the messages' ``frame`` (the 0-based frame number in the source).
Without a source only the 3D skeletons, their states and confidences are shown. A sequence
folder is its own source: without ``poses.jsonl`` (as ``swarmpose synth`` writes it) its depth
and colour are shown without bodies.

:func:`log_recording` logs it all into a :class:`~swarmpose.publish.rerun_view.RerunSink`
in frame order, the same entities as a live ``--view``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

from swarmpose.core.errors import SourceError
from swarmpose.publish.rerun_view import RerunSink
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source

POSES_FILE = "poses.jsonl"


def poses_file(recording: str | Path) -> Path | None:
    """The ``poses.jsonl`` of ``recording`` (that file itself, or one in that folder); None
    when ``recording`` is a folder without one. SourceError when it does not exist."""
    path = Path(recording)
    if path.is_file():
        return path
    if path.is_dir():
        return path / POSES_FILE if (path / POSES_FILE).is_file() else None
    raise SourceError(f"{recording}: no such file or folder; pass a folder written by replay/track --out "
                      f"(with {POSES_FILE}) or a sequence folder")


def read_messages(path: Path) -> Iterator[dict]:
    """The frame messages of a ``poses.jsonl`` file, in file order. A line that is not a
    frame message raises SourceError naming the file and line (blank lines are skipped)."""
    try:
        with open(path, encoding="utf-8") as lines:
            for number, line in enumerate(lines, 1):
                if not line.strip():
                    continue
                try:
                    message = json.loads(line)
                    int(message["frame"])
                    if not isinstance(message.get("bodies", []), list):
                        raise TypeError("bodies is not a list")
                except (ValueError, KeyError, TypeError) as exc:
                    raise SourceError(f"{path} line {number} is not a swarmpose.frame message ({exc}); pass the "
                                      f"{POSES_FILE} a run wrote (a run killed mid-line leaves a last line cut "
                                      "short: delete it)") from exc
                yield message
    except OSError as exc:
        raise SourceError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise SourceError(f"{path} is not UTF-8 JSON lines ({exc}); pass the {POSES_FILE} a run wrote") from exc


def empty_message(frame: Frame, camera: str) -> dict:
    """A frame message without bodies for a source frame the recording has no message for."""
    return {"schema": "swarmpose.frame", "camera": camera, "frame": frame.index, "capture_ns": frame.timestamp_ns,
            "latency_ms": 0.0, "reason": "", "coordinates": "camera", "camera_to_world": None, "bodies": []}


def log_recording(sink: RerunSink, recording: str | Path, source: str = "", camera: str = "camera0") -> int:
    """Log the recording at ``recording`` (see the module docstring) with the frames of
    ``source`` (a source URI; empty: none, unless ``recording`` is itself a sequence folder)
    into ``sink``; returns the number of frames logged.

    Every message is logged once, in the order of its ``frame``; a source frame without a
    message is logged without bodies; messages beyond the source's end without a frame.
    """
    poses = poses_file(recording)
    folder = Path(recording)
    if not source and (poses is None or (folder.is_dir() and (folder / "depth").is_dir())):
        source = str(folder)  # a sequence folder (with or without the poses of a run written into it)
    messages = {int(m["frame"]): m for m in read_messages(poses)} if poses is not None else {}
    logged = 0
    if source:
        with open_source(source) as frames:
            for item in frames:
                message = messages.pop(item.index, None)
                if isinstance(item, Frame):
                    sink.frame(message or empty_message(item, camera), item)
                    logged += 1
                elif message is not None:
                    sink.frame(message, None)
                    logged += 1
    for index in sorted(messages):
        sink.frame(messages[index], None)
        logged += 1
    return logged
