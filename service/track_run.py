"""Run the tracker over a frame source: detection, tracking, one JSON line per frame.

Every frame yields one record, written and flushed before the next frame is read, so an
interrupted run keeps everything it produced:

* a tracked frame: :meth:`swarmpose.tracker.TrackResult.as_dict` (state init / tracking / lost);
* a frame the source could not deliver: ``{"frame", "timestamp_ns", "state": "skipped", "reason"}``;
* a frame whose detector or tracker failed: state ``lost`` with the error as the reason
  (the track restarts from the next detection).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .camera import Intrinsics
from .errors import OutputError, SwarmposeError
from .progress import Progress
from .sources.base import Frame, SkippedFrame
from .tracker import Tracker, TrackResult


@dataclass
class TrackRun:
    """What a run produced: records (one dict per frame, in order), estimates
    {frame index: (14, 3) joints m}, the wall time (s) of detection + tracking, and
    counts per state."""

    records: list[dict] = field(default_factory=list)
    estimates: dict[int, np.ndarray] = field(default_factory=dict)
    seconds: float = 0.0
    states: dict[str, int] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return len(self.records)

    @property
    def fps(self) -> float:
        """Frames per second of detection + tracking (file reading excluded)."""
        tracked = sum(v for k, v in self.states.items() if k != "skipped")
        return tracked / self.seconds if self.seconds > 0 else 0.0


def _open_output(out: Path | None):
    if out is None:
        return None
    try:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        return open(out, "w", encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}; choose a writable --out") from exc


def track_source(source, detector, tracker: Tracker | Callable[[Intrinsics], Tracker], out: Path | None = None,
                 max_frames: int | None = None, progress: bool = True) -> TrackRun:
    """Track every frame of ``source`` (an iterable of Frame / SkippedFrame) with ``detector``
    (a :class:`~swarmpose.joints2d.base.Detector`), writing JSON lines to ``out`` if given.

    tracker: a Tracker, or a factory called with the first frame's intrinsics.
    """
    run = TrackRun()
    total = max_frames or getattr(source, "length", None) or 0
    bar = Progress("track", total, enabled=progress and total > 0)
    sink = _open_output(out)
    last: TrackResult | None = None
    try:
        for item in source:
            if max_frames is not None and run.frames >= max_frames:
                break
            if isinstance(item, SkippedFrame):
                record = {"frame": item.index, "timestamp_ns": item.timestamp_ns, "state": "skipped",
                          "reason": item.reason}
            else:
                if not isinstance(tracker, Tracker):
                    tracker = tracker(item.intrinsics)
                t0 = time.perf_counter()
                record, last = _track_frame(item, detector, tracker, last)
                run.seconds += time.perf_counter() - t0
                if last is not None and np.any(np.isfinite(last.joints3d)):
                    run.estimates[item.index] = last.joints3d
            run.records.append(record)
            run.states[record["state"]] = run.states.get(record["state"], 0) + 1
            if sink is not None:
                sink.write(json.dumps(record, allow_nan=False) + "\n")
                sink.flush()
            bar.update(run.frames)
    finally:
        if sink is not None:
            sink.close()
    return run


def _track_frame(frame: Frame, detector, tracker: Tracker, last: TrackResult | None) -> tuple[dict, TrackResult | None]:
    try:
        joints = detector.detect(frame, None if last is None else last.joints_box())
    except SwarmposeError as exc:
        joints, note = None, f"detector failed: {exc}"
    else:
        note = ""
    try:
        result = tracker.step(frame, joints)
    except SwarmposeError as exc:
        tracker.reset()
        return {"frame": frame.index, "timestamp_ns": frame.timestamp_ns, "state": "lost",
                "reason": f"tracking failed: {exc}"}, None
    record = result.as_dict()
    if note:
        record["reason"] = "; ".join(r for r in (note, record["reason"]) if r)
    if joints is not None:
        record["detections"] = {"layout": joints.layout.name, "keypoints": joints.as_dict()}
    return record, result
