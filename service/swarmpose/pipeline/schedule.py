"""When the live worker's detection takes its next frame: just in time for the tracker.

Live, the tracker takes the newest detected frame when it is done with the last one. A frame
detected as soon as the tracker started waits in between for most of a tracking period, and its
pose comes that much later. So the frame detection takes waits until the tracker is due to finish
less the time a detection takes, and then gives way to the newest frame, if another came meanwhile:
the frame is as fresh as it can be when the tracker takes it, and detection still runs beside the end
of the search. Once that moment has passed and the tracker is still busy, detection takes every new
frame at once, so the one waiting stays fresh.

The tracker is due after the median of its last :data:`RECENT_FRAMES` frames. A track's start or a
re-check takes several times a usual frame; a running mean would carry such a frame into the next
few frames' waits, and the frame detected at the start of each would wait there for a whole slow
frame's time. The median ignores the odd slow frame. Detection's own time is a running mean, one for
the frames it segments and one for those it detects whole (a person tracked alone is segmented every
few frames only, and a segmented frame's detection takes several times as long).

A newer frame can still be in detection when the tracker finishes: detection took it when it came,
and it comes at the camera's own moments, not the tracker's. The tracker then waits for it when it is
due within :data:`WAIT_SHARE` of how much newer it is and at most :data:`MAX_WAIT_S`
(:meth:`JustInTime.fresher_s`): a frame one camera period fresher for a few milliseconds of waiting.
"""

from __future__ import annotations

import collections
import statistics
import threading
import time

from swarmpose.tracking.budget import running_mean

RECENT_FRAMES = 9
"""How many of the tracker's last frames the median tracking time is taken over."""
WAIT_SHARE = 0.5
"""The tracker waits for a newer frame in detection at most this share of how much newer it is."""
MAX_WAIT_S = 0.025
"""...and never longer than this (s)."""
WAIT_SLACK_S = 0.005
"""Beyond a newer frame's due end, how much longer the tracker gives its detection (within the limits)."""


class JustInTime:
    """The median tracking time of the last frames, the running means of the detection times (of
    segmented frames and of frames detected whole), and how long detection should wait."""

    def __init__(self):
        self._lock = threading.Lock()
        self._recent: collections.deque[float] = collections.deque(maxlen=RECENT_FRAMES)
        self.track_s: float | None = None
        """The median of the last :data:`RECENT_FRAMES` tracking times (s); None before the first."""
        self.detect_s: dict[bool, float] = {}
        """The running mean detection time (s) of segmented (True) and whole-frame (False) detections."""
        self._tracking_since: float | None = None
        self._detecting: tuple[float, bool, int] | None = None  # (started, segmented, captured ns)
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
                self._recent.append(time.monotonic() - self._tracking_since)
                self.track_s = statistics.median(self._recent)
            self._tracking_since = None
            self.idle.set()

    def detecting(self, started: float, segmented: bool, received_ns: int) -> None:
        """Detection is on a frame taken from the source at ``received_ns`` (wall clock, ns) since ``started``
        (``time.monotonic()``, where its time is counted from); ``segmented``: it segments it."""
        with self._lock:
            self._detecting = (started, segmented, received_ns)

    def detected(self, seconds: float, segmented: bool = False) -> None:
        """A detection took ``seconds`` and its frame is handed over; ``segmented``: it segmented its frame."""
        with self._lock:
            self.detect_s[segmented] = running_mean(self.detect_s.get(segmented), seconds)
            self._detecting = None

    def fresher_s(self, received_ns: int) -> float | None:
        """How long the tracker, about to take a frame taken from the source at ``received_ns``, should
        wait for the newer frame in detection (s); None: none is, or it is not worth the wait (module
        docstring)."""
        with self._lock:
            if self._detecting is None:
                return None
            started, segmented, newer_ns = self._detecting
            detect_s = self._detect_time(segmented)
        if detect_s is None or newer_ns <= received_ns:
            return None
        left = max(started + detect_s - time.monotonic(), 0.0)
        limit = min(WAIT_SHARE * (newer_ns - received_ns) * 1e-9, MAX_WAIT_S)
        return min(left + WAIT_SLACK_S, limit) if left <= limit else None

    def _detect_time(self, segmented: bool) -> float | None:
        """(lock held) The running mean time of a detection of this kind, else of the other; None: none yet."""
        return self.detect_s.get(segmented, self.detect_s.get(not segmented))

    def wait(self, segmenting: bool = False) -> None:
        """Wait until detection should take the next frame: :meth:`wait_s`, or less when the tracker
        finishes its frame first."""
        seconds = self.wait_s(segmenting)
        if seconds > 0:
            self.idle.wait(seconds)

    def wait_s(self, segmenting: bool = False) -> float:
        """How long detection should wait before it takes the next frame (0: take it now); ``segmenting``:
        the next detection segments its frame (the other kind's time until this kind's is known)."""
        with self._lock:
            detect_s = self._detect_time(segmenting)
            if self._tracking_since is None or self.track_s is None or detect_s is None:
                return 0.0
            due = self._tracking_since + self.track_s - detect_s
        return max(due - time.monotonic(), 0.0)
