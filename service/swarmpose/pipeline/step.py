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

With ``max_people`` > 1 the detection half first finds the people in the depth
(:func:`swarmpose.detect.people.segment_people`) and runs the detector on each one's crop
(:func:`swarmpose.detect.per_person.detect_each`); the tracking half gives them to a
:class:`~swarmpose.people.people_tracker.PeopleTracker` (one track and id per person).
Where the segmentation finds nobody, the frame is detected and tracked as with one person. Live,
while it finds the one tracked person alone, only every :data:`SEGMENT_ALONE_EVERY`-th frame is
segmented (the frames between are detected whole).

With a :class:`~swarmpose.pipeline.world.WorldFrame` (``--floor``), the detection half fits the
floor until it is known and the tracking half sets the world origin under the first tracked
person; every result carries the world state and the coordinates wanted in its message.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, SwarmposeError
from swarmpose.detect.floor import FloorPlane
from swarmpose.detect.joints import Detector, Joints2D
from swarmpose.detect.people import Segmentation, segment_people
from swarmpose.detect.per_person import PersonDetection, detect_each
from swarmpose.detect.props import PropMemory
from swarmpose.detect.steady_boxes import SteadyBoxes
from swarmpose.gpu.errors import DeviceError
from swarmpose.people.people_tracker import PeopleTracker
from swarmpose.pipeline.velocity import JointVelocities
from swarmpose.pipeline.world import NOT_FITTED, WorldFrame
from swarmpose.sources.base import Frame, SkippedFrame, exc_message
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import tracker_default
from swarmpose.tracking.result import FrameResult

log = logging.getLogger(__name__)
FLOOR_REFIT_FRAMES = 15
"""The floor plane is fitted again every this many segmented frames (8 ms a fit; a camera may move)."""
NOBODY = "no person found (none in the depth whose detection shows a person)"
EMPTY_DEPTH = "the depth image has no valid pixels (every one 0: no measurement)"
SEGMENT_ALONE_EVERY = 4
"""Live (a frame period set), while exactly one person is tracked and the last segmentation found them
alone (nobody else, no prop beside them), only every this many-th frame is segmented; the frames
between are detected whole, as with one person. The lone person's fit depth is the same either way
(nothing is left out of it), and on 2 cores the segmentation's CPU (15-20 ms a frame) slowed the
search in the other thread. Someone who comes into view is found at the next segmented frame."""


@dataclass
class Detection:
    """The first half's answer for one frame: joints (None: none), a note when the detector
    failed, and the detection time (ms, the segmentation's ``segment_ms`` included). With several
    people: ``people`` (each person's segment and joints; None in single-person mode), the
    ``segmentation`` they came from (None when it found nobody and the whole frame was detected)
    and ``props``: (H, W) bool pixels of the props beside people that the pipeline's memory knows
    and sees again (:mod:`swarmpose.detect.props`), left out of every person's depth; None: none."""

    joints: Joints2D | None
    note: str = ""
    ms: float = 0.0
    people: tuple[PersonDetection, ...] | None = None
    segmentation: Segmentation | None = None
    segment_ms: float = 0.0
    props: np.ndarray | None = None
    unsegmented: bool = False
    """Live, the frame was detected whole because the last segmentation found the one tracked person
    alone (:data:`SEGMENT_ALONE_EVERY`)."""

    @property
    def timings_ms(self) -> dict[str, float]:
        """``detect`` (the 2D network and the rest of detection) and ``segment`` (people in the depth), ms."""
        return {"detect": self.ms - self.segment_ms, "segment": self.segment_ms}


def describe_error(exc: BaseException) -> str:
    """An exception as a one-line reason: our own errors by their message, others with their type."""
    return str(exc) if isinstance(exc, SwarmposeError) else f"{type(exc).__name__}: {exc_message(exc)}"


@dataclass
class FloorCache:
    """The floor plane the segmentation reuses: fitted on a camera, used for
    :data:`FLOOR_REFIT_FRAMES` segmented frames of it, then fitted again (a camera may move)."""

    plane: FloorPlane | None = None
    intrinsics: Intrinsics | None = None
    frames: int = 0

    def reusable(self, intrinsics: Intrinsics) -> bool:
        """Whether the plane may serve another frame of camera ``intrinsics``."""
        return self.plane is not None and self.intrinsics == intrinsics and self.frames < FLOOR_REFIT_FRAMES

    def used(self, plane: FloorPlane | None, intrinsics: Intrinsics, fitted: bool) -> None:
        """Count a frame segmented with ``plane`` (``fitted``: fitted anew on it)."""
        if fitted:
            self.plane, self.intrinsics, self.frames = plane, intrinsics, 0
        self.frames += 1


class FramePipeline:
    """Detect and track frames of one camera.

    detector: a :class:`~swarmpose.detect.joints.Detector`; make_tracker: builds a
    :class:`~swarmpose.tracking.body_tracker.BodyTracker` for a camera's intrinsics and a
    body id; max_people: 1 tracks one person (no segmentation), more tracks each person the
    depth segmentation finds, up to this many; retire_frames: frames a person may go unseen
    before its id is retired; personalise_frames: N when ``make_tracker`` builds trackers that
    personalise their body from N frames (``--personalize``, or the automatic height's upright
    frames), else 0; world: the camera's
    world frame (floor, origin, coordinates of the messages), None: camera frame only;
    backward: the offline backward pass's window in frames (:mod:`swarmpose.pipeline.backward`,
    run by :func:`swarmpose.pipeline.run.results`), 0: none; centred_sigma_s: σ (s) of the
    offline centred smoothing of the published poses (:mod:`swarmpose.pipeline.centred_smoothing`,
    run there too), 0: none; box_hold: the share of its size a track's crop box may move and still
    be held (:mod:`swarmpose.detect.steady_boxes`), 0: the box of the tracked joints every frame.
    ``detect`` and ``track`` may run in two threads (one each).
    """

    def __init__(self, detector: Detector, make_tracker: Callable[[Intrinsics, int], BodyTracker],
                 max_people: int, retire_frames: int = tracker_default("retire_frames"), personalise_frames: int = 0,
                 world: WorldFrame | None = None, backward: int = 0, centred_sigma_s: float = 0.0,
                 box_hold: float = tracker_default("box_hold")):
        self.detector, self.make_tracker = detector, make_tracker
        self.backward, self.centred_sigma_s = int(backward), float(centred_sigma_s)
        self.on_step = None
        """Given to every tracker made from now on as its ``on_step`` (the offline backward pass)."""
        self.max_people, self.retire_frames = int(max_people), int(retire_frames)
        self.personalise_frames = int(personalise_frames)
        self.world = world
        self.tracker: BodyTracker | None = None
        self.people: PeopleTracker | None = None
        self.intrinsics: Intrinsics | None = None
        self._box: np.ndarray | None = None
        self._boxes: list[np.ndarray] = []  # the last frame's tracked bodies' joint boxes (several people)
        self._steady = SteadyBoxes(box_hold)  # each track's box, held while its joints stay put
        self._floor = FloorCache()
        self._props = PropMemory()
        self.velocities = JointVelocities()
        self.frame_period_s: float | None = None
        """The camera's frame period (s), given to every tracker (live: frames dropped widen the search)."""
        self.budget_ms = 0.0
        """The time a frame's tracking may take (ms), shared by its people (live; 0: the configured search)."""
        self._box_lock = threading.Lock()
        self._alone = 0  # frames since a segmentation found one person alone (0: it did not; used live only)
        self._detector_stale = False  # reset() since the last detection: the detector forgets its crops first
        self._warned_empty = False  # a depth image without valid pixels is logged once

    @property
    def device_name(self) -> str:
        """The OpenCL device the tracker scores on ("" before the first frame, or in lift mode)."""
        if self.people is not None:
            return self.people.device_name
        return "" if self.tracker is None else self.tracker.device_name

    @property
    def personalisation(self) -> dict | None:
        """``{"needed": N, "bodies": [each tracked body's state]}`` with ``--personalize N`` or the
        automatic height (``personalise_frames``), None without: the status and info messages'
        ``personalisation``."""
        if not self.personalise_frames:
            return None
        if self.people is not None:
            bodies = self.people.personalisation()
        else:
            state = None if self.tracker is None else self.tracker.personalisation()
            bodies = [] if state is None else [state]
        return {"needed": self.personalise_frames, "bodies": bodies}

    def body_of(self, body_id: int) -> SkinnedBody | None:
        """The body the tracker of ``body_id`` tracks with now (its locked shape once
        ``--personalize`` has fitted it), None where no tracker has that id."""
        if self.people is not None:
            return self.people.body_of(body_id)
        if self.tracker is not None and self.tracker.body_id == body_id:
            return self.tracker.body
        return None

    def detect(self, frame: Frame) -> Detection:
        """2D joints of ``frame``: of each person the depth shows (``max_people`` > 1), else of
        the one person, looking first where the last tracked body was."""
        t0 = time.perf_counter()
        detection = self._detect(frame)
        if self.world is not None:  # the floor until known (the segmentation's own fit where it made one)
            seg, cached = detection.segmentation, self._floor.plane
            fitted = seg.floor if seg is not None else cached if detection.unsegmented and cached else NOT_FITTED
            self.world.observe_depth(frame, fitted)
            detection.ms = 1000 * (time.perf_counter() - t0)
        return detection

    def _detect(self, frame: Frame) -> Detection:
        """:meth:`detect` without the floor of the world frame."""
        t0 = time.perf_counter()
        with self._box_lock:
            stale = self._detector_stale
        if stale:
            self.reset_detector()
        segmentation, segment_ms, props = None, 0.0, None
        unsegmented = self.max_people > 1 and self._unsegmented()
        if self.max_people > 1 and not unsegmented:
            try:
                reuse = self._floor.reusable(frame.intrinsics)
                props = self._props.known(frame.depth, frame.intrinsics)
                if props is not None and log.isEnabledFor(logging.DEBUG):  # a full-frame count: only when shown
                    log.debug("frame %d: %d pixels of known props left out", frame.index, int(props.sum()))
                segmentation = segment_people(frame.depth, frame.intrinsics, max_people=2 * self.max_people,
                                              floor=self._floor.plane if reuse else "auto", background=props)
                self._floor.used(segmentation.floor, frame.intrinsics, fitted=not reuse)
                if segmentation.people:  # a frame with nobody says nothing of what stands beside someone
                    self._props.learn(frame.depth, frame.intrinsics, segmentation.props)
            except Exception as exc:  # a segmentation that throws: the frame is detected as a whole
                log.debug("frame %d: segmentation failed: %s", frame.index, exc_message(exc))
            segment_ms = 1000 * (time.perf_counter() - t0)
            alone = (segmentation is not None and len(segmentation.people) == 1 and segmentation.props is None
                     and self._props.empty)
            with self._box_lock:  # reset() runs in the tracking thread
                self._alone = 1 if alone else 0
        if segmentation is not None and segmentation.people:
            with self._box_lock:
                hints = list(self._boxes)
            try:
                people = detect_each(self.detector, frame, segmentation, hints)
            except Exception as exc:  # e.g. a colour image of another size: the frame is detected as a whole
                log.debug("frame %d: detection per person failed: %s", frame.index, exc_message(exc))
                segmentation = None
            else:
                note = "; ".join(p.note for p in people if p.note)
                return Detection(people[0].joints, note, 1000 * (time.perf_counter() - t0), people, segmentation,
                                 segment_ms, props)
        with self._box_lock:
            box = self._box
        try:
            joints, note = self.detector.detect(frame, box), ""
        except Exception as exc:  # a detector that throws: the frame goes on without joints
            joints, note = None, f"detector failed: {exc_message(exc)}"
            log.debug("frame %d: %s", frame.index, note)
        if not np.any(frame.depth > 0):  # 0 (and NaN) = no measurement: nobody can be found in it
            note = "; ".join(n for n in (note, EMPTY_DEPTH) if n)
            if not self._warned_empty:
                self._warned_empty = True
                log.warning("frame %d: %s; check the depth stream (units, registration to colour); such frames "
                            "are tracked as having nobody in view", frame.index, EMPTY_DEPTH)
        people = (PersonDetection(None, joints, note),) if self.max_people > 1 else None
        return Detection(joints, note, 1000 * (time.perf_counter() - t0), people, segmentation, segment_ms, props,
                         unsegmented)

    def segments_next(self) -> bool:
        """Whether the next detection segments its frame (it is counted by the detection, not here)."""
        with self._box_lock:
            return self.max_people > 1 and not self._alone_skips()

    def _alone_skips(self) -> bool:
        """(``_box_lock`` held) whether a frame now is detected whole: live, one person tracked, whom the
        last segmentation, fewer than :data:`SEGMENT_ALONE_EVERY` frames ago, found alone."""
        return (self.frame_period_s is not None and 0 < self._alone < SEGMENT_ALONE_EVERY and len(self._boxes) == 1
                and self._box is not None)

    def _unsegmented(self) -> bool:
        """Whether this frame is detected whole without a segmentation (:meth:`_alone_skips`), counted."""
        with self._box_lock:
            one = self._alone_skips()
            self._alone = self._alone + 1 if one else 0
        return one

    def track(self, frame: Frame, detection: Detection, received_ns: int = 0) -> FrameResult:
        """The bodies of ``frame`` given its detection; never raises for a frame it cannot track.
        received_ns: wall-clock time (ns) the frame was taken from its source (0: unknown). Each
        tracked body carries its joints' velocities (:mod:`~swarmpose.pipeline.velocity`)."""
        return self.in_world(self.velocities(self._track(frame, detection, received_ns)))

    def in_world(self, result: FrameResult) -> FrameResult:
        """``result`` with the world state as known after it (the origin set by its first tracked
        body if still unknown) and the coordinates its message should use."""
        if self.world is None:
            return result
        return replace(result, world=self.world.observe_bodies(result.bodies), coordinates=self.world.coordinates)

    def _track(self, frame: Frame, detection: Detection, received_ns: int) -> FrameResult:
        """:meth:`track` without the world frame."""
        t0 = time.perf_counter()
        if detection.people is not None:
            return self._track_people(frame, detection, received_ns, t0)
        try:
            if self.tracker is None or self.intrinsics != frame.intrinsics:
                self.tracker, self.intrinsics = self._new_tracker(frame.intrinsics, 0), frame.intrinsics
            body = self.tracker.step(frame, detection.joints)
        except Exception as exc:  # a frame that fails to track: no bodies, restart the track
            if self.tracker is not None:
                self.tracker.reset()
            return self._failed(frame, detection, exc, received_ns, t0)
        with self._box_lock:
            self._box = self._steady.update({body.id: body.joints_box()}).get(body.id)
        timings = {**detection.timings_ms, **body.timings_ms}
        timings["total"] = detection.ms + body.timings_ms.get("total", 1000 * (time.perf_counter() - t0))
        return FrameResult(frame.index, frame.timestamp_ns, (body,), detection.note, timings, received_ns=received_ns)

    def _new_tracker(self, intrinsics: Intrinsics, body_id: int) -> BodyTracker:
        tracker = self.make_tracker(intrinsics, body_id)
        tracker.on_step, tracker.frame_period_s, tracker.budget_ms = self.on_step, self.frame_period_s, self.budget_ms
        return tracker

    def _track_people(self, frame: Frame, detection: Detection, received_ns: int, t0: float) -> FrameResult:
        """The several-people half of :meth:`track`."""
        try:
            if self.people is None or self.intrinsics != frame.intrinsics:
                intrinsics, old = frame.intrinsics, self.people
                if old is not None:  # a new camera: new trackers, the ids and counts go on
                    old.reset()
                self.people = PeopleTracker(lambda body_id: self._new_tracker(intrinsics, body_id), self.max_people,
                                            self.retire_frames, first_id=0 if old is None else old.next_id,
                                            counts=None if old is None else old.counts)
                self.intrinsics = intrinsics
            labels = None if detection.segmentation is None else detection.segmentation.labels
            self.people.budget_ms = self.budget_ms / max(len(detection.people), 1)
            self.people.live = self.frame_period_s is not None
            bodies = self.people.step(frame, detection.people, labels, detection.props)
        except Exception as exc:  # a frame that fails to track (not one person's fit): every track restarts
            if self.people is not None:
                self.people.reset()
            return self._failed(frame, detection, exc, received_ns, t0)
        with self._box_lock:
            boxes = self._steady.update({b.id: b.joints_box() for b in bodies if b.state != "lost"})
            self._box = boxes.get(bodies[0].id) if len(bodies) == 1 else None
            self._boxes = list(boxes.values())
        timings: dict[str, float] = dict(detection.timings_ms)
        for body in bodies:  # each body's parts (start, search, launch, ...) summed over the people
            for key, ms in body.timings_ms.items():
                timings[key] = timings.get(key, 0.0) + ms
        timings["track"] = 1000 * (time.perf_counter() - t0)
        timings["total"] = detection.ms + timings["track"]
        found = (int(detection.joints is not None) if detection.unsegmented
                 else sum(p.segment is not None for p in detection.people))
        people = {"tracked": sum(b.state != "lost" for b in bodies), "found": found, **self.people.counts.as_dict()}
        reason = detection.note if bodies else "; ".join(r for r in (detection.note, NOBODY) if r)
        return FrameResult(frame.index, frame.timestamp_ns, bodies, reason, timings, received_ns=received_ns,
                           people=people)

    def _failed(self, frame: Frame, detection: Detection, exc: BaseException, received_ns: int,
                t0: float) -> FrameResult:
        """The result of a frame whose tracking threw: no bodies, the reason, and no box to
        look in next (the tracks restart from the next detection). A setting no frame can be tracked
        with (an OpenCL device that is not there, a bad option) is raised: the run stops on it."""
        if isinstance(exc, (ConfigError, DeviceError)):
            raise exc
        with self._box_lock:
            self._box, self._boxes = None, []
            self._steady.reset()
        reason = "; ".join(r for r in (detection.note, f"tracking failed: {describe_error(exc)}") if r)
        return FrameResult(frame.index, frame.timestamp_ns, (), reason,
                           {**detection.timings_ms, "total": detection.ms + 1000 * (time.perf_counter() - t0)},
                           received_ns=received_ns)

    def process(self, item: Frame | SkippedFrame) -> FrameResult:
        """Detect and track one source item (a skipped frame gives a result saying why)."""
        received_ns = time.time_ns()
        if isinstance(item, SkippedFrame):
            return self.in_world(skipped_result(item, received_ns))
        return self.track(item, self.detect(item), received_ns)

    def reset(self, detector: bool = True) -> None:
        """Forget the tracks, the bodies fitted to their people, the detector's box, the props seen (a
        camera that came back may stand elsewhere) and, with ``detector``, what the detector remembers
        of earlier frames (its next detection resets it first; False: the caller resets it in the
        detection's own thread, :meth:`reset_detector`, as the live worker does)."""
        if self.tracker is not None:
            self.tracker.new_person()
        if self.people is not None:
            self.people.reset()
        self.velocities.reset()
        self._props = PropMemory()
        with self._box_lock:
            self._box, self._boxes, self._alone = None, [], 0
            self._steady.reset()
            self._detector_stale = self._detector_stale or detector

    def reset_detector(self) -> None:
        """Make the detector forget what it remembers of earlier frames (BlazePose's regions), now: call it
        in the detection's thread, where every detector call runs."""
        with self._box_lock:
            self._detector_stale = False
        if hasattr(self.detector, "reset"):
            self.detector.reset()


def skipped_result(item: SkippedFrame, received_ns: int = 0) -> FrameResult:
    """The result of a frame the source could not deliver."""
    return FrameResult(item.index, item.timestamp_ns, (), f"skipped: {item.reason}", {}, skipped=True,
                       received_ns=received_ns)
