"""When the live worker's detection takes its next frame: just in time for the tracker.

Live, the tracker takes the newest detected frame when it is done with the last one. A frame
detected as soon as the tracker started waits in between for most of a tracking period, and its
pose comes that much later. So detection waits until the tracker is due to finish less the time a
detection takes (running means of both), then takes the newest frame: the frame is as fresh as it
can be when the tracker takes it, and detection still runs beside the end of the search.
"""

from __future__ import annotations

import threading
import time

from swarmpose.tracking.budget import running_mean


class JustInTime:
    """Running means of the tracking and detection times, and how long detection should wait."""

    def __init__(self):
        self._lock = threading.Lock()
        self.track_s: float | None = None
        self.detect_s: float | None = None
        self._tracking_since: float | None = None
        self.idle = threading.Event()
        """Set while the tracker is between frames (a waiting detection wakes when it finishes early)."""
        self.idle.set()

    def tracking(self) -> None:
        """The tracker started a frame."""
        with self._lock:
            self._tracking_since = time.monotonic()
            self.idle.clear()

    def tracked(self) -> None:
        """The tracker finished its frame."""
        with self._lock:
            if self._tracking_since is not None:
                self.track_s = running_mean(self.track_s, time.monotonic() - self._tracking_since)
            self._tracking_since = None
            self.idle.set()

    def detected(self, seconds: float) -> None:
        """A detection took ``seconds``."""
        with self._lock:
            self.detect_s = running_mean(self.detect_s, seconds)

    def wait(self) -> None:
        """Wait until detection should take the next frame: :meth:`wait_s`, or less when the tracker
        finishes its frame first."""
        seconds = self.wait_s()
        if seconds > 0:
            self.idle.wait(seconds)

    def wait_s(self) -> float:
        """How long detection should wait before it takes the next frame (0: take it now)."""
        with self._lock:
            if self._tracking_since is None or self.track_s is None or self.detect_s is None:
                return 0.0
            due = self._tracking_since + self.track_s - self.detect_s
        return max(due - time.monotonic(), 0.0)
