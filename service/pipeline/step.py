"""The one per-frame step: detect → track → result, used by every way of running swarmpose
(``track``, ``eval``, ``replay``, ``serve`` and the Python API).

:class:`FramePipeline` owns the detector's feedback (the box around the last tracked body's
joints, where the detector looks next) and the tracker, built for the first frame's camera
(and again when the camera changes). Its two halves run in one thread
(:meth:`FramePipeline.process`) or in two (the worker's detection and tracking threads):

* :meth:`~FramePipeline.detect`: a detector that throws gives no joints and a note (the
  frame's ``reason``); the frame is still tracked (on depth alone);
* :meth:`~FramePipeline.track`: a tracker that throws gives a frame without bodies whose
  reason says why, and the track restarts from the next detection.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SwarmposeError
from swarmpose.detect.joints import Detector, Joints2D
from swarmpose.sources.base import Frame, SkippedFrame, exc_message
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.result import FrameResult

log = logging.getLogger(__name__)


@dataclass
class Detection:
    """The first half's answer for one frame: joints (None: none), a note when the detector
    failed, and the detection time (ms)."""

    joints: Joints2D | None
    note: str = ""
    ms: float = 0.0


def describe_error(exc: BaseException) -> str:
    """An exception as a one-line reason: our own errors by their message, others with their type."""
    return str(exc) if isinstance(exc, SwarmposeError) else f"{type(exc).__name__}: {exc_message(exc)}"


class FramePipeline:
    """Detect and track frames of one camera.

    detector: a :class:`~swarmpose.detect.joints.Detector`; make_tracker: builds a
    :class:`~swarmpose.tracking.body_tracker.BodyTracker` for a camera's intrinsics.
    ``detect`` and ``track`` may run in two threads (one each).
    """

    def __init__(self, detector: Detector, make_tracker: Callable[[Intrinsics], BodyTracker]):
        self.detector, self.make_tracker = detector, make_tracker
        self.tracker: BodyTracker | None = None
        self.intrinsics: Intrinsics | None = None
        self._box: np.ndarray | None = None
        self._box_lock = threading.Lock()

    @property
    def device_name(self) -> str:
        """The OpenCL device the tracker scores on ("" before the first frame, or in lift mode)."""
        return "" if self.tracker is None else self.tracker.device_name

    def detect(self, frame: Frame) -> Detection:
        """2D joints of ``frame``, looking first where the last tracked body was."""
        with self._box_lock:
            box = self._box
        t0 = time.perf_counter()
        try:
            joints, note = self.detector.detect(frame, box), ""
        except Exception as exc:  # a detector that throws: the frame goes on without joints
            joints, note = None, f"detector failed: {exc_message(exc)}"
            log.debug("frame %d: %s", frame.index, note)
        return Detection(joints, note, 1000 * (time.perf_counter() - t0))

    def track(self, frame: Frame, detection: Detection, received_ns: int = 0) -> FrameResult:
        """The bodies of ``frame`` given its detection; never raises for a frame it cannot track.
        received_ns: wall-clock time (ns) the frame was taken from its source (0: unknown)."""
        t0 = time.perf_counter()
        try:
            if self.tracker is None or self.intrinsics != frame.intrinsics:
                self.tracker, self.intrinsics = self.make_tracker(frame.intrinsics), frame.intrinsics
            body = self.tracker.step(frame, detection.joints)
        except Exception as exc:  # a frame that fails to track: no bodies, restart the track
            if self.tracker is not None:
                self.tracker.reset()
            reason = "; ".join(r for r in (detection.note, f"tracking failed: {describe_error(exc)}") if r)
            with self._box_lock:
                self._box = None
            return FrameResult(frame.index, frame.timestamp_ns, (), reason,
                               {"detect": detection.ms, "total": detection.ms + 1000 * (time.perf_counter() - t0)},
                               received_ns=received_ns)
        with self._box_lock:
            self._box = body.joints_box()
        timings = {"detect": detection.ms, **body.timings_ms}
        timings["total"] = detection.ms + body.timings_ms.get("total", 1000 * (time.perf_counter() - t0))
        return FrameResult(frame.index, frame.timestamp_ns, (body,), detection.note, timings, received_ns=received_ns)

    def process(self, item: Frame | SkippedFrame) -> FrameResult:
        """Detect and track one source item (a skipped frame gives a result saying why)."""
        received_ns = time.time_ns()
        if isinstance(item, SkippedFrame):
            return skipped_result(item, received_ns)
        return self.track(item, self.detect(item), received_ns)

    def reset(self) -> None:
        """Forget the track and the detector's box."""
        if self.tracker is not None:
            self.tracker.reset()
        with self._box_lock:
            self._box = None


def skipped_result(item: SkippedFrame, received_ns: int = 0) -> FrameResult:
    """The result of a frame the source could not deliver."""
    return FrameResult(item.index, item.timestamp_ns, (), f"skipped: {item.reason}", {}, skipped=True,
                       received_ns=received_ns)
