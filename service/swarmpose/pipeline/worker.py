"""The long-running worker: acquisition, detection and tracking threads, publishing to sinks.

Three threads hand frames over through one-slot queues (:class:`~.handover.Handover`):

    source --acquire--> [slot] --detect--> [slot] --track--> message --> sinks

Detection and tracking are the two halves of the one per-frame step
(:class:`~swarmpose.pipeline.step.FramePipeline`).

* **live** (``drop_stale=True``, ``swarmpose serve``): a slot holds only the newest frame;
  when a stage is slower than the camera, the waiting older frame is dropped and counted,
  so the tracker always works on the newest frame; detection takes its frame just in time for
  the tracker (:mod:`~.schedule`);
* **replay** (``drop_stale=False``, ``swarmpose replay``): a full slot makes the stage before
  it wait; every frame is processed, as fast as the slowest stage goes.

Latency of a frame = wall-clock time from the moment acquisition took it from the source
(``received_ns``) to the moment its message is made (``publish_ns``). In replay every
stage runs ahead of the next and frames queue, so there the waits are left out:
``received_ns`` is shifted to count from when detection took the frame, minus the time it
then waited for the tracker; the latency is the processing time (detection + tracking). Every
``status_period_s`` the worker sends a ``swarmpose.status`` message to its sinks (zenoh,
and the status-only sinks of :mod:`swarmpose.pipeline.status`: health file, log).

Failures never stop the worker where it can go on: a detector exception tracks the frame
without joints; a tracker exception publishes the frame without bodies and restarts the
track; a sink that fails is reported once and gets no more messages (the others go on; its
failure is kept in ``sink_errors``); a live source that fails is
reopened every ``reopen_s`` seconds; a recording that ends or fails ends the run (or starts
over with ``loop``). A source opened again (looped or reopened) starts the tracks afresh.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from swarmpose.pipeline.handover import END, Handover
from swarmpose.pipeline.schedule import JustInTime
from swarmpose.pipeline.status import WorkerStats, status_message
from swarmpose.pipeline.step import Detection, FramePipeline, describe_error, skipped_result
from swarmpose.publish.sink import Sink
from swarmpose.sources.base import DeferredFrame, Frame, FrameSource, SkippedFrame, exc_message, warn_skipped

log = logging.getLogger(__name__)
MAX_ERRORS = 20
JOIN_TIMEOUT_S = 30.0
ACQUIRE_JOIN_S = 2.0


@dataclass
class Received:
    """A source item with the wall-clock time (ns) acquisition took it, and its detection."""

    item: Frame | SkippedFrame | DeferredFrame
    received_ns: int
    detection: Detection | None = None
    detected_ns: int = 0
    opening: int = 0  # which opening of the source (a loop or a reopen starts a new one) it came from


class Worker:
    """Runs the pipeline until the source ends, ``frames`` are received or :meth:`stop`.

    open_source: opens the frame source (called again to reopen or loop); pipeline: the
    per-frame step; sinks: where messages go (see :class:`~swarmpose.publish.sink.Sink`);
    camera: the camera id; drop_stale: live (True) or replay (False) hand-overs; pace_fps:
    deliver a recording at this rate (None: as fast as it reads); loop: start a recording
    over when it ends; frames: stop after this many (0 = all); source_uri / detector_spec:
    for the status; zenoh_state: a callable returning the status' ``zenoh`` part; source:
    the already opened source (None: ``open_source()``); on_acquired: called by the acquisition
    thread with every item it takes from the source and the wall-clock time (ns) it took it (the
    camera's clock, as ``swarmpose bench live`` reads it).
    """

    def __init__(self, open_source: Callable[[], FrameSource], pipeline: FramePipeline, sinks: Sequence[Sink],
                 *, camera: str, drop_stale: bool, pace_fps: float | None = None, loop: bool = False,
                 frames: int = 0, status_period_s: float = 1.0, reopen_s: float = 5.0, source_uri: str = "",
                 detector_spec: str = "", zenoh_state: Callable[[], dict] | None = None,
                 source: FrameSource | None = None,
                 on_acquired: Callable[[Frame | SkippedFrame | DeferredFrame, int], None] | None = None):
        self.open_source, self.pipeline, self.sinks = open_source, pipeline, list(sinks)
        self.on_acquired = on_acquired
        self.camera, self.drop_stale, self.pace_fps, self.loop = camera, drop_stale, pace_fps, loop
        self.frames, self.status_period_s, self.reopen_s = frames, status_period_s, reopen_s
        self.source_uri, self.detector_spec, self.zenoh_state = source_uri, detector_spec, zenoh_state
        self.source = source if source is not None else open_source()
        self.source_state = "running"
        self.state = "starting"
        self.stats = WorkerStats(keep_all=not drop_stale, personalisation=pipeline.personalisation or {})
        self.errors: collections.deque[str] = collections.deque(maxlen=MAX_ERRORS)
        self.sink_errors: list[str] = []
        """One line per sink that failed on a frame (it got nothing more)."""
        self._live_sinks = list(self.sinks)
        self._deferred_skips = 0
        self._timing = JustInTime()
        self._opening = self._tracked_opening = self._detected_opening = 0
        self._stop = threading.Event()
        self._done = threading.Event()
        self._lock = threading.Lock()
        self._acquired = Handover(drop_stale)
        self._detected = Handover(drop_stale)
        self._started = time.monotonic()
        self._period_start = time.monotonic()

    @property
    def intrinsics(self):
        """The camera of the frames tracked so far (None before the first)."""
        return self.pipeline.intrinsics

    @property
    def opencl_device(self) -> str:
        return self.pipeline.device_name

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """Ask every thread to finish (from a signal handler or another thread).

        Takes no lock of the worker's: a signal handler runs in the main thread, between two
        of its bytecodes, possibly while that thread holds ``_lock`` (a status being made),
        and would wait for itself forever. The Event is set before the state is written, and
        :meth:`_set_state` looks at the Event again after writing, so "stopping" stays."""
        self._stop.set()
        self.state = "stopping"
        self._timing.idle.set()  # a detection waiting for the tracker goes on to see the stop
        self._acquired.abort()
        self._detected.abort()

    def _set_state(self, state: str) -> None:
        """Change the worker state, unless it is already stopping (a stop is final)."""
        with self._lock:
            if not self._stop.is_set():
                self.state = state
                if self._stop.is_set():  # stop() came in between: its "stopping" wins
                    self.state = "stopping"

    def report(self, message: str) -> None:
        """Keep an error message for the next status (newest last) and log it."""
        log.warning("%s", message)
        with self._lock:
            self.errors.append(message)

    def run(self) -> WorkerStats:
        """Run until done; sends a status every period and a last one at the end. Closes the sinks."""
        threads = [threading.Thread(target=self._guard, args=(fn,), name=f"swarmpose {name}", daemon=True)
                   for name, fn in (("acquire", self._acquire), ("detect", self._detect), ("track", self._track))]
        # "starting" until the first frame is published (opening the source, compiling the kernels, the first fit)
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
                    except Exception as exc:  # report (a sink that failed before: once is enough), go on
                        if sink in self._live_sinks:
                            self.report(f"closing {type(sink).__name__}: {exc_message(exc)}")
                        else:
                            log.debug("closing %s: %s", type(sink).__name__, exc_message(exc))
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
                self.source, self._opening = source, self._opening + 1
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

    def _enough(self) -> bool:
        return bool(self.frames) and self.stats.received >= self.frames

    def _read_all(self, source: FrameSource) -> None:
        start_wall, start_capture = None, None
        pace = self.pace_fps and not source.live
        source.defer = bool(pace and self.drop_stale and source.can_defer)  # decode only the frames kept
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
            self.stats.update(received=1)
            received_ns = time.time_ns()
            if self.on_acquired is not None:
                self.on_acquired(item, received_ns)
            if not self._acquired.put(Received(item, received_ns, opening=self._opening)):
                self.stats.update(dropped=1)
            if self._enough():
                return

    def _detect(self) -> None:
        try:
            while True:
                segmenting = self.pipeline.segments_next()
                got = self._acquired.get()
                if self.drop_stale and got is not END:  # live: just in time for the tracker
                    got = self._newest_when_due(got, segmenting)
                    if self._stop.is_set():
                        return
                started = time.monotonic()
                if got is END:
                    return
                if not self.drop_stale:
                    got.received_ns = time.time_ns()  # replay reads ahead: count latency from here
                if isinstance(got.item, DeferredFrame):  # a recording's frame, read now that it is taken
                    got.item = got.item.read()
                    if isinstance(got.item, SkippedFrame):
                        self._deferred_skips += 1
                        warn_skipped(self.source_uri, got.item, self._deferred_skips)
                took = None
                if got.opening != self._detected_opening:  # a new take: the detector starts afresh, before
                    self._detected_opening = got.opening    # its first frame (the tracker resets the rest)
                    self.pipeline.reset_detector()
                if isinstance(got.item, Frame):
                    self._timing.detecting(started, segmenting, got.received_ns)
                    got.detection = self.pipeline.detect(got.item)
                    took = time.monotonic() - started
                    if got.detection.note:
                        self.stats.update(detector_errors=1, detector_error=got.detection.note)
                        self.report(got.detection.note)
                got.detected_ns = time.time_ns()
                if not self._detected.put(got):
                    self.stats.update(dropped=1)
                if took is not None:  # after the hand-over: the tracker may wait for it until then
                    self._timing.detected(took, got.detection.segment_ms > 0)
        finally:
            self._detected.finish()

    def _track(self) -> None:
        try:
            while True:
                got = self._detected.get()
                if got is END:
                    return
                if self.drop_stale:
                    got = self._fresher(got)
                    if self._stop.is_set():
                        return
                else:  # replay: leave out the wait for the previous frame's tracking
                    got.received_ns += time.time_ns() - got.detected_ns
                if got.opening != self._tracked_opening:  # the recording started over (or the camera came back):
                    self.pipeline.reset(detector=False)      # its people are new, where the old ones were is no help
                    self._tracked_opening = got.opening
                self._timing.tracking()
                self._publish(got)
                self._timing.tracked()
        finally:
            self._done.set()

    def _newest_when_due(self, got: Received, segmenting: bool) -> Received:
        """Live: the frame detection took waits until detection is due (:mod:`~.schedule`), then gives
        way to the newest one, if another came meanwhile; past that moment it is detected at once."""
        if self._timing.wait_s(segmenting) <= 0:
            return got
        self._timing.wait(segmenting)
        return self._newer(got, self._acquired, 0.0)

    def _fresher(self, got: Received) -> Received:
        """Live: ``got``, or the newer frame in detection when it is due soon enough to wait for
        (:meth:`~.schedule.JustInTime.fresher_s`)."""
        wait = self._timing.fresher_s(got.received_ns)
        return got if wait is None else self._newer(got, self._detected, wait)

    def _newer(self, got: Received, slot: Handover, timeout: float) -> Received:
        """The item ``slot`` gives within ``timeout`` s (``got`` is then a dropped frame), else ``got``."""
        newer = slot.get(timeout=timeout)
        if newer is None or newer is END:  # none came, or the source ended (the next get says so again)
            return got
        self.stats.update(dropped=1)
        return newer

    def _result(self, got: Received):
        """The frame result of one received item, counted."""
        if isinstance(got.item, SkippedFrame):
            self.stats.update(skipped=1)
            return self.pipeline.in_world(skipped_result(got.item, got.received_ns))
        result = self.pipeline.track(got.item, got.detection, got.received_ns)
        personalisation = self.pipeline.personalisation
        if personalisation is not None:  # --personalize: every body's state, none once everybody has left
            self.stats.update(personalisation=personalisation)
        if result.people is not None:  # several people: a frame without anybody in view is no failure
            state = result.bodies[0].state if result.bodies else "none"
            self.stats.update(tracker_state=state, people=dict(result.people))
        elif not result.bodies:  # the tracker failed on this frame
            self.stats.update(failed=1, tracker_failures=1, tracker_error=result.reason, tracker_state="lost")
            self.report(result.reason)
        else:
            self.stats.update(tracker_state=result.bodies[0].state, failed=1 if result.reason else 0)
        return result

    def _publish(self, got: Received) -> None:
        message = self._result(got).to_message(self.camera, received_ns=got.received_ns)
        frame = got.item if isinstance(got.item, Frame) else None
        for sink in list(self._live_sinks):
            try:
                sink.frame(message, frame)
            except Exception as exc:  # one failing sink must not stop the others; it gets no more
                what = f"{type(sink).__name__}: {describe_error(exc)}"
                self._live_sinks.remove(sink)
                self.sink_errors.append(what)
                self.report(f"{what}; it gets no more messages")
        self.stats.update(latency_ms=message["latency_ms"], published=1, period_published=1)
        if self.state == "starting":
            self._set_state("running")

    # ------------------------------------------------------------------ status
    def status_message(self) -> dict:
        """The current ``swarmpose.status`` message; starts a new status period."""
        now = time.monotonic()
        with self._lock:
            period = max(now - self._period_start, self.status_period_s)
            self._period_start = now
            errors = list(self.errors)
        zenoh = self.zenoh_state() if self.zenoh_state else None
        return status_message(self.camera, self.state, self.stats, period, now - self._started,
                              source_uri=self.source_uri, source_state=self.source_state,
                              detector_spec=self.detector_spec, zenoh=zenoh, opencl_device=self.opencl_device,
                              errors=errors)

    def _send_status(self) -> None:
        try:
            message = self.status_message()
        except Exception as exc:  # e.g. zenoh's state while the session closes: skip this status
            self.report(f"status: {type(exc).__name__}: {exc_message(exc)}")
            return
        for sink in list(self._live_sinks):
            try:
                sink.status(message)
            except Exception as exc:  # keep going; the next status carries the error
                self.report(f"{type(sink).__name__} status: {exc_message(exc)}")
