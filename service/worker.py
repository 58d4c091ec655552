"""The long-running worker: acquisition, detection and tracking threads, publishing to sinks.

Three threads hand frames over through one-slot queues (:class:`Handover`):

    source --acquire--> [slot] --detect--> [slot] --track--> message --> sinks

* **live** (``drop_stale=True``, ``swarmpose serve``): a slot holds only the newest frame;
  when a stage is slower than the camera, the waiting older frame is dropped and counted,
  so the tracker always works on the newest frame;
* **replay** (``drop_stale=False``, ``swarmpose replay``): a full slot makes the stage before
  it wait; every frame is processed, as fast as the slowest stage goes.

Latency of a frame = wall-clock time from the moment acquisition took it from the source
(``received_ns``) to the moment its message is made (``publish_ns``). In replay every
stage runs ahead of the next and frames queue, so there the waits are left out:
``received_ns`` is shifted to count from when detection took the frame, minus the time it
then waited for the tracker; the latency is the processing time (detection + tracking). Every
``status_period_s`` the worker sends a ``swarmpose.status`` message (fps and latency over
the period, frame counters, source / detector / tracker / zenoh state, recent errors) to
its sinks and to ``log``.

Failures never stop the worker where it can go on: a detector exception tracks the frame
without joints; a tracker exception publishes the frame without bodies and restarts the
track; a sink that fails is reported and the others go on; a live source that fails is
reopened every ``reopen_s`` seconds; a recording that ends or fails ends the run (or starts
over with ``loop``).
"""

from __future__ import annotations

import collections
import json
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import SwarmposeError
from .messages import body_entry, frame_message
from .sources.base import Frame, FrameSource, SkippedFrame, exc_message

END = object()
"""Put through the hand-overs after the last frame."""
MAX_ERRORS = 20
JOIN_TIMEOUT_S = 30.0
ACQUIRE_JOIN_S = 2.0


class Handover:
    """A one-item queue between two threads.

    drop_stale: ``put`` replaces a waiting item (returns False: one was dropped) instead of
    waiting for the consumer. ``finish()`` lets ``get`` return :data:`END` once the last item
    is taken; ``abort()`` makes every waiting call return at once (``get`` gives END).
    """

    def __init__(self, drop_stale: bool):
        self.drop_stale = drop_stale
        self._cond = threading.Condition()
        self._item: object | None = None
        self._full = False
        self._finished = False
        self._aborted = False

    def put(self, item: object) -> bool:
        """Hand ``item`` over; False when a waiting older item was dropped for it."""
        with self._cond:
            dropped = False
            if self._full and self.drop_stale:
                dropped = True
            else:
                while self._full and not self._aborted:
                    self._cond.wait()
            if self._aborted:
                return True
            self._item, self._full = item, True
            self._cond.notify_all()
            return not dropped

    def get(self) -> object:
        """The next item, waiting for it; END after ``finish()`` or ``abort()``."""
        with self._cond:
            while not self._full and not self._finished and not self._aborted:
                self._cond.wait()
            if self._aborted or not self._full:
                return END
            item, self._item, self._full = self._item, None, False
            self._cond.notify_all()
            return item

    def finish(self) -> None:
        with self._cond:
            self._finished = True
            self._cond.notify_all()

    def abort(self) -> None:
        with self._cond:
            self._aborted = True
            self._cond.notify_all()


@dataclass
class Received:
    """A source item with the wall-clock time (ns) acquisition took it."""

    item: Frame | SkippedFrame
    received_ns: int
    joints: object = None
    note: str = ""
    detected_ns: int = 0


@dataclass
class WorkerStats:
    """Counters since the start (see ``frames`` in protocol/status.schema.json) and the
    latencies (ms) and publish times of the current status period."""

    received: int = 0
    published: int = 0
    dropped: int = 0
    skipped: int = 0
    failed: int = 0
    detector_errors: int = 0
    tracker_failures: int = 0
    period_latencies: list[float] = field(default_factory=list)
    all_latencies: list[float] = field(default_factory=list)
    last_latency: float | None = None
    tracker_state: str = "none"
    detector_error: str = ""
    tracker_error: str = ""


class Worker:
    """Runs the pipeline until the source ends, ``max_frames`` are received or :meth:`stop`.

    open_source: opens the frame source (called again to reopen or loop); detector: a
    :class:`~swarmpose.joints2d.base.Detector`; make_tracker: builds a
    :class:`~swarmpose.tracker.Tracker` for a frame's intrinsics; sinks: where messages go
    (see :class:`~swarmpose.publish.sink.Sink`); camera: the camera id; drop_stale: live
    (True) or replay (False) hand-overs; pace_fps: deliver a recording at this rate (None:
    as fast as it reads); loop: start a recording over when it ends; max_frames: 0 = all;
    log: called with each status message (None: quiet); info: extra fields for
    status (``source_uri``, ``detector``, ``opencl_device``) and ``zenoh_state`` a callable
    returning the status' ``zenoh`` part.
    """

    def __init__(self, open_source: Callable[[], FrameSource], detector, make_tracker: Callable, sinks: Sequence,
                 *, camera: str, drop_stale: bool, pace_fps: float | None = None, loop: bool = False,
                 max_frames: int = 0, status_period_s: float = 1.0, reopen_s: float = 5.0,
                 source_uri: str = "", detector_spec: str = "", health_file: str = "",
                 zenoh_state: Callable[[], dict] | None = None, log: Callable[[dict], None] | None = None,
                 source: FrameSource | None = None):
        self.open_source, self.detector, self.make_tracker = open_source, detector, make_tracker
        self.sinks = list(sinks)
        self.camera, self.drop_stale, self.pace_fps, self.loop = camera, drop_stale, pace_fps, loop
        self.max_frames, self.status_period_s, self.reopen_s = max_frames, status_period_s, reopen_s
        self.source_uri, self.detector_spec, self.health_file = source_uri, detector_spec, health_file
        self.zenoh_state, self.log = zenoh_state, log
        self.source = source if source is not None else open_source()
        self.source_state = "running"
        self.state = "starting"
        self.tracker = None
        self.intrinsics = None
        self.opencl_device = ""
        self.stats = WorkerStats()
        self.errors: collections.deque[str] = collections.deque(maxlen=MAX_ERRORS)
        self._stop = threading.Event()
        self._done = threading.Event()
        self._lock = threading.Lock()
        self._acquired = Handover(drop_stale)
        self._detected = Handover(drop_stale)
        self._last_box: np.ndarray | None = None
        self._started = time.monotonic()
        self._period_start = time.monotonic()
        self._period_published = 0

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """Ask every thread to finish (from a signal handler or another thread)."""
        with self._lock:
            self._stop.set()
            self.state = "stopping"
        self._acquired.abort()
        self._detected.abort()

    def _set_state(self, state: str) -> None:
        """Change the worker state, unless it is already stopping (a stop is final)."""
        with self._lock:
            if not self._stop.is_set():
                self.state = state

    def report(self, message: str) -> None:
        """Keep an error message for the next status (newest last)."""
        with self._lock:
            self.errors.append(message)

    def run(self) -> WorkerStats:
        """Run until done; sends a status every period and a last one at the end. Closes the sinks."""
        threads = [threading.Thread(target=self._guard, args=(fn,), name=f"swarmpose {name}", daemon=True)
                   for name, fn in (("acquire", self._acquire), ("detect", self._detect), ("track", self._track))]
        self._set_state("running")
        for t in threads:
            t.start()
        try:
            while not self._done.wait(self.status_period_s):
                self._send_status()
        except KeyboardInterrupt:
            self.stop()
        finally:
            try:
                if not self._done.is_set():
                    self.stop()
                # tracking and detection first (they finish their frame); acquisition may be blocked
                # inside a camera read that cannot be interrupted, so it gets a short wait only
                for t in reversed(threads):
                    t.join(JOIN_TIMEOUT_S if t is not threads[0] else ACQUIRE_JOIN_S)
                if self.state != "failed":
                    self._set_state("source-failed" if self.source_state.startswith("error") else "source-ended")
                self._send_status()
            finally:
                for sink in self.sinks:
                    try:
                        sink.close()
                    except Exception as exc:  # report, close the others
                        self.report(f"closing {type(sink).__name__}: {exc_message(exc)}")
        return self.stats

    def _guard(self, fn: Callable[[], None]) -> None:
        """Run a thread's loop; an unexpected exception is reported and ends the run cleanly."""
        try:
            fn()
        except Exception as exc:  # a bug must not leave the other threads waiting forever
            self.report(f"{threading.current_thread().name} crashed: {type(exc).__name__}: {exc_message(exc)}")
            self.stop()
            self.state = "failed"
            self._done.set()

    # ------------------------------------------------------------------ threads
    def _acquire(self) -> None:
        source = self.source
        try:
            while not self._stop.is_set():
                try:
                    self._read_all(source)
                except Exception as exc:  # a source failing before its first frame (e.g. after a reopen)
                    source.status = f"error: {exc_message(exc)}"
                self.source_state = "ended" if source.status in ("open", "ended") else source.status
                source.close()
                if self._stop.is_set() or self._enough():
                    break
                if self.source_state == "ended" and not self.loop:
                    break
                if self.source_state.startswith("error") and not (source.live or self.loop):
                    self.report(f"source {self.source_uri}: {self.source_state}")
                    break
                if self.source_state.startswith("error"):
                    self._set_state("source-failed")
                    self.report(f"source {self.source_uri}: {self.source_state}; reopening in {self.reopen_s:g} s")
                source = self._reopen()
                if source is None:
                    break
                self.source = source
                self._set_state("running")
        finally:
            self._acquired.finish()

    def _reopen(self) -> FrameSource | None:
        """The source opened again (live: after reopen_s, retrying until it works or stop)."""
        delay = 0.0 if self.source_state == "ended" else self.reopen_s
        while not self._stop.wait(delay):
            try:
                source = self.open_source()
            except Exception as exc:  # any driver error: report it and try again later
                self.source_state = f"error: {exc}"
                self.report(f"reopening {self.source_uri}: {exc}")
                delay = self.reopen_s
                continue
            self.source_state = "running"
            return source
        return None

    def _count_drop(self) -> None:
        with self._lock:
            self.stats.dropped += 1

    def _enough(self) -> bool:
        return bool(self.max_frames) and self.stats.received >= self.max_frames

    def _read_all(self, source: FrameSource) -> None:
        start_wall, start_capture = None, None
        pace = self.pace_fps and not source.live
        if self._enough():
            return
        for item in source:
            if self._stop.is_set():
                return
            if pace:
                if start_wall is None:
                    start_wall, start_capture = time.monotonic(), item.index
                wait = start_wall + (item.index - start_capture) / self.pace_fps - time.monotonic()
                if wait > 0 and self._stop.wait(wait):
                    return
            self.stats.received += 1
            if not self._acquired.put(Received(item, time.time_ns())):
                self._count_drop()
            if self._enough():
                return

    def _detect(self) -> None:
        try:
            while True:
                got = self._acquired.get()
                if got is END:
                    return
                if not self.drop_stale:
                    got.received_ns = time.time_ns()  # replay reads ahead: count latency from here
                if isinstance(got.item, Frame):
                    try:
                        got.joints = self.detector.detect(got.item, self._last_box)
                    except Exception as exc:  # a detector that throws: the frame goes on without joints
                        got.note = f"detector failed: {exc_message(exc)}"
                        self.stats.detector_errors += 1
                        self.stats.detector_error = got.note
                        self.report(got.note)
                got.detected_ns = time.time_ns()
                if not self._detected.put(got):
                    self._count_drop()
        finally:
            self._detected.finish()

    def _track(self) -> None:
        try:
            while True:
                got = self._detected.get()
                if got is END:
                    return
                if not self.drop_stale:  # replay: leave out the wait for the previous frame's tracking
                    got.received_ns += time.time_ns() - got.detected_ns
                self._publish(got, *self._track_one(got))
        finally:
            self._done.set()

    def _track_one(self, got: Received) -> tuple[list[dict], str, dict]:
        """(bodies, reason, timings) of one received item."""
        item = got.item
        if isinstance(item, SkippedFrame):
            self.stats.skipped += 1
            return [], f"skipped: {item.reason}", {}
        try:
            if self.tracker is None or self.intrinsics != item.intrinsics:
                self.tracker, self.intrinsics = self.make_tracker(item.intrinsics), item.intrinsics
                self.opencl_device = _device_name(self.tracker)
            result = self.tracker.step(item, got.joints)
        except Exception as exc:  # a frame that fails to track: publish it without bodies, restart the track
            if self.tracker is not None:
                self.tracker.reset()
            what = str(exc) if isinstance(exc, SwarmposeError) else f"{type(exc).__name__}: {exc_message(exc)}"
            reason = f"tracking failed: {what}"
            self.stats.failed += 1
            self.stats.tracker_failures += 1
            self.stats.tracker_error = reason
            self.stats.tracker_state = "lost"
            self.report(reason)
            return [], "; ".join(r for r in (got.note, reason) if r), {}
        self.stats.tracker_state = result.state
        self._last_box = result.joints_box()
        if got.note:
            self.stats.failed += 1
        return [body_entry(result)], got.note, result.timings_ms

    def _publish(self, got: Received, bodies: list[dict], reason: str, timings: dict) -> None:
        publish_ns = time.time_ns()
        message = frame_message(self.camera, got.item.index, got.item.timestamp_ns, got.received_ns, publish_ns,
                                bodies, reason=reason, timings_ms=timings)
        frame = got.item if isinstance(got.item, Frame) else None
        for sink in self.sinks:
            try:
                sink.frame(message, frame)
            except Exception as exc:  # one failing sink must not stop the others
                self.report(f"{type(sink).__name__}: {exc_message(exc)}")
        latency = message["latency_ms"]
        with self._lock:
            self.stats.published += 1
            self._period_published += 1
            self.stats.last_latency = latency
            self.stats.period_latencies.append(latency)
            if not self.drop_stale:  # replay reports them all at the end; serve runs for days
                self.stats.all_latencies.append(latency)

    # ------------------------------------------------------------------ status
    def status_message(self) -> dict:
        """The current ``swarmpose.status`` message; starts a new status period."""
        now = time.monotonic()
        with self._lock:
            lat = np.array(self.stats.period_latencies)
            self.stats.period_latencies = []
            fps = self._period_published / max(now - self._period_start, self.status_period_s)
            self._period_start, self._period_published = now, 0
            errors = list(self.errors)
        s = self.stats
        zenoh = self.zenoh_state() if self.zenoh_state else {"mode": "off", "connect": [], "listen": [], "peers": 0,
                                                               "routers": 0, "warning": ""}
        return {
            "schema": "swarmpose.status", "version": 1, "camera": self.camera, "time_ns": time.time_ns(),
            "uptime_s": round(now - self._started, 3), "state": self.state, "fps": round(fps, 3),
            "latency_ms": {**latency_summary(lat), "last": s.last_latency},
            "frames": {"received": s.received, "published": s.published, "dropped": s.dropped,
                       "skipped": s.skipped, "failed": s.failed},
            "source": {"uri": self.source_uri, "state": self.source_state},
            "detector": {"spec": self.detector_spec, "errors": s.detector_errors, "last_error": s.detector_error},
            "tracker": {"state": s.tracker_state, "failures": s.tracker_failures, "last_error": s.tracker_error},
            "zenoh": zenoh, "opencl_device": self.opencl_device, "errors": errors,
        }

    def _send_status(self) -> None:
        try:
            message = self.status_message()
        except Exception as exc:  # e.g. zenoh's state while the session closes: skip this status
            self.report(f"status: {type(exc).__name__}: {exc_message(exc)}")
            return
        for sink in self.sinks:
            try:
                sink.status(message)
            except Exception as exc:  # keep going; the next status carries the error
                self.report(f"{type(sink).__name__} status: {exc_message(exc)}")
        if self.health_file:
            write_health_file(self.health_file, message)
        if self.log:
            try:
                self.log(message)
            except Exception:  # a closed stderr must not stop the worker
                pass


def latency_summary(latencies_ms) -> dict:
    """``{"median", "p95"}`` of latencies (ms), None for an empty list."""
    lat = np.asarray(latencies_ms, float)
    if not lat.size:
        return {"median": None, "p95": None}
    return {"median": round(float(np.median(lat)), 3), "p95": round(float(np.percentile(lat, 95)), 3)}


def _device_name(tracker) -> str:
    scorer = getattr(getattr(tracker, "objective", None), "scorer", None)
    device = getattr(scorer, "device", None)
    return "" if device is None else f"{device.platform.name.strip()}: {device.name.strip()}"


def write_health_file(path: str, message: dict) -> None:
    """Write the status message atomically (temporary file + rename) for ``swarmpose health``."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(message), encoding="utf-8")
        os.replace(tmp, target)
    except OSError:
        pass  # health reporting must never stop the worker; `swarmpose health` then reports a stale file


def format_status(message: dict) -> str:
    """One log line of a status message."""
    f, lat = message["frames"], message["latency_ms"]
    latency = "n/a" if lat["median"] is None else f"{lat['median']:.0f} ms (p95 {lat['p95']:.0f})"
    line = (f"[{message['camera']}] {message['state']}: {message['fps']:.2f} fps, latency {latency}, "
            f"frames {f['published']}/{f['received']} published (dropped {f['dropped']}, skipped {f['skipped']}, "
            f"failed {f['failed']}), source {message['source']['state']}, tracker {message['tracker']['state']}")
    if message["zenoh"]["warning"]:
        line += f"; zenoh: {message['zenoh']['warning']}"
    return line
