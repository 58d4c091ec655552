"""Run a 2D detector in its own thread, at its own rate, beside the tracker.

The paper's OpenPose ran at about 10 fps while the tracker ran at camera rate; the
tracker uses the newest detection it has. :class:`DetectorThread` does that:

* ``submit(frame, box)`` hands over a frame without waiting; only the newest pending frame
  is kept, an older pending one is dropped (counted in ``dropped``);
* the thread detects on the pending frame, no more often than ``rate_hz`` (None: as fast as
  the detector goes), and keeps the result;
* ``latest()`` is the newest detection (or None), ``age_ns(frame)`` how old it is relative to
  ``frame`` (capture times, ns), ``wall_age_s()`` how long ago it finished (seconds);
* an exception from the detector is caught, counted in ``errors`` and kept in
  ``last_error``; the thread goes on with the next frame;
* ``close()`` stops and joins the thread (idempotent; also on leaving a ``with`` block)
  and closes the detector unless ``close_detector=False``.

Counters: ``submitted == processed + errors + dropped`` once the thread is idle or closed.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ..errors import ConfigError, DetectorError
from .base import Detector, Joints2D

JOIN_TIMEOUT_S = 30.0


class DetectorThread:
    """A detector running in a background thread on the newest submitted frame.

    detector: any :class:`~swarmpose.joints2d.base.Detector`; rate_hz: most detections per
    second (None = unlimited); close_detector: close the detector in :meth:`close`.
    """

    def __init__(self, detector: Detector, rate_hz: float | None = None, close_detector: bool = True):
        if rate_hz is not None and not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"detector rate must be a positive number of Hz, got {rate_hz}")
        self.detector = detector
        self.rate_hz = rate_hz
        self.close_detector = close_detector
        self.submitted = 0
        self.processed = 0
        self.dropped = 0
        self.errors = 0
        self.last_error: Exception | None = None
        self._cond = threading.Condition()
        self._pending: tuple[object, np.ndarray | None] | None = None
        self._busy = False
        self._closed = False
        self._latest: Joints2D | None = None
        self._latest_done = 0.0
        self._thread = threading.Thread(target=self._run, name=f"detector {getattr(detector, 'name', '?')}",
                                        daemon=True)
        self._thread.start()

    # -- the tracker's side -------------------------------------------------------------------
    def submit(self, frame, box: np.ndarray | None = None) -> bool:
        """Queue ``frame`` (with an optional crop ``box`` [x0, y0, x1, y1] px) for detection; never blocks.

        Returns True when an older pending frame was dropped for it. DetectorError after :meth:`close`.
        """
        with self._cond:
            if self._closed:
                raise DetectorError("the detector thread is closed; cannot submit frames to it")
            dropped = self._pending is not None
            if dropped:
                self.dropped += 1
            self._pending = (frame, None if box is None else np.asarray(box, dtype=np.float64).reshape(4))
            self.submitted += 1
            self._cond.notify_all()
            return dropped

    def latest(self) -> Joints2D | None:
        """The newest detection, None before the first one."""
        with self._cond:
            return self._latest

    def age_ns(self, frame) -> int | None:
        """``frame.timestamp_ns`` minus the newest detection's frame time (ns); None before the first one."""
        latest = self.latest()
        return None if latest is None else int(frame.timestamp_ns) - int(latest.timestamp_ns)

    def wall_age_s(self) -> float | None:
        """Seconds (wall clock) since the newest detection finished; None before the first one."""
        with self._cond:
            return None if self._latest is None else time.monotonic() - self._latest_done

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until no frame is pending or being detected; False if ``timeout`` (s) ran out first."""
        with self._cond:
            return self._cond.wait_for(lambda: self._closed or (self._pending is None and not self._busy), timeout)

    @property
    def alive(self) -> bool:
        """Whether the detection thread is running."""
        return self._thread.is_alive()

    def stats(self) -> dict:
        """Counters and the last error, for status reports."""
        with self._cond:
            return {"detector": getattr(self.detector, "name", "?"), "rate_hz": self.rate_hz,
                    "submitted": self.submitted, "processed": self.processed, "dropped": self.dropped,
                    "errors": self.errors, "last_error": None if self.last_error is None else str(self.last_error)}

    def close(self) -> None:
        """Stop the thread (a pending frame is dropped, a running detection finishes), join it; idempotent."""
        with self._cond:
            if not self._closed:
                self._closed = True
                if self._pending is not None:
                    self._pending = None
                    self.dropped += 1
                self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(JOIN_TIMEOUT_S)
        if self.close_detector and not self._thread.is_alive():
            self.close_detector = False
            self.detector.close()

    def __enter__(self) -> DetectorThread:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the detection thread -------------------------------------------------------------------
    def _run(self) -> None:
        next_start = 0.0
        while True:
            with self._cond:
                while not self._closed and self._pending is None:
                    self._cond.wait()
                if self._closed:
                    return
                delay = next_start - time.monotonic()
                if delay > 0:
                    self._cond.wait(delay)  # a newer frame may replace the pending one meanwhile
                    continue
                frame, box = self._pending
                self._pending = None
                self._busy = True
            started = time.monotonic()
            if self.rate_hz is not None:
                next_start = started + 1.0 / self.rate_hz
            result, error = None, None
            try:
                result = self.detector.detect(frame, box)
            except Exception as exc:  # a detector failure must not stop the thread
                error = exc
            with self._cond:
                if error is None:
                    self._latest = result
                    self._latest_done = time.monotonic()
                    self.processed += 1
                else:
                    self.errors += 1
                    self.last_error = error
                self._busy = False
                self._cond.notify_all()
