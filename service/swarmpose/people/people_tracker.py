"""Several people at once: one :class:`~swarmpose.tracking.body_tracker.BodyTracker` per person,
each with a stable id.

Per frame (:meth:`PeopleTracker.step`), given the people the depth segmentation found and
each one's 2D joints (:func:`swarmpose.detect.per_person.detect_each`):

1. **Association** (:mod:`swarmpose.people.association`): the tracks' expected centres
   (last segment centre moved by the track's velocity) against the segments' centres, plus
   their colour histograms; Hungarian assignment with a gate.
2. **Each matched track** runs its own PSO on the frame with *the other people's pixels
   removed from the depth* (set to 0, no measurement): a person in front of this one then
   neither pulls its model forward nor counts against the model's hidden parts, since the
   depth term skips pixels without a measurement (paper Eq. 2). The props beside people
   (:mod:`swarmpose.detect.props`: a table, a stool) are removed from every fit's depth the same
   way. A track whose fit is lost keeps its id: its tracker restarts from the detection on the
   next frame.
3. **New people** (segments no track took), largest first, get a new track while fewer than
   ``max_people`` are tracked; the id is given only when the first fit finds a person. A
   segment whose detection has no torso at the tracker's ``min_score`` is tried once more on
   its own pixels alone, from the keypoints down to :data:`START_MIN_SCORE` (the segment
   confirms what the network doubts); one that still has no torso takes no id. The rest are
   counted as ``beyond_max_people``.
4. **Tracks not seen** this frame keep their id and state for ``retire_frames`` frames (a
   short occlusion or a crossing), then are retired; ids are never reused. For the first
   :data:`COAST_FRAMES` of those frames the track is followed on the depth alone (a person
   mostly hidden behind another is often too small a piece to be segmented) and reported,
   with the reason :data:`COASTING`, while its fit is not lost.

Only the people seen (or followed) in a frame are reported in it. Where the segmentation found nobody (no
person separable from the background: a person against a wall, a cut-off upper body) the
caller passes one observation without a segment (the detector on the whole frame), which
takes the most recently seen track or a new one, on the unmasked depth.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.detect.per_person import PersonDetection
from swarmpose.people.association import NO_PAIR, Assignment, assign, colour_histogram, pair_costs
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import tracker_default
from swarmpose.tracking.init_pose import NO_TORSO
from swarmpose.tracking.result import BodyResult

log = logging.getLogger(__name__)

GATE_M = 0.8
"""A track and a segment farther apart than this (m, plus the appearance term) never pair."""
DROPPED_GATE_M = 0.05
"""Live (``PeopleTracker.live``), the gate widens by this (m) for every frame dropped since the last one
tracked: a person walking at 1.5 m/s moves that far from one frame of a 30 fps camera to the next.
(Offline no frame is dropped; a frame the source could not deliver leaves the gate as it is.)"""
APPEARANCE_M = 0.5
"""Metres of centre distance that completely different colours weigh."""
VELOCITY_BLEND = 0.5
"""Share of the newest frame-to-frame motion in a track's velocity (exponential smoothing)."""
LOOK_BLEND = 0.2
"""Share of the newest colour histogram in a track's appearance."""
COAST_FRAMES = 15
"""A track not found in the segmentation (mostly hidden behind someone) is followed on the depth
alone (no detection; every segmented person's pixels removed) for up to this many frames, and
reported while its fit is not lost."""
START_MIN_SCORE = 0.1
"""A new person's segment whose detection has no torso at ``min_score`` starts its track from the
keypoints down to this score, on the depth of its segment alone: the second person of the real
Skeltrack frame 1399145206, whose head another's raised hand hides, gets hips of 0.23 and 0.37 from
MoveNet on its crop (its shoulders, 0.12-0.13, find no depth of its own: they lie under the hand)
and starts from both hips (:func:`~swarmpose.tracking.init_pose.torso_pose`). 0.2 would do for
that frame; 0.1 leaves room for a weaker one. The segment-only depth leaves the model free outside
the segment for that first fit: keypoints on the background find no depth, and the following
frames are fitted on the whole depth as any other's."""
COASTING = "not found in the depth segmentation (hidden?): followed on the depth alone"


@dataclass
class Track:
    """One person's track: id, its body tracker, where it was (centre (3,) m, camera frame),
    its velocity (3,) m per frame, its colour histogram, and frames since it was last seen."""

    id: int
    tracker: BodyTracker
    centre: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    look: np.ndarray | None = None
    last_frame: int = 0
    missed: int = 0

    def expected(self, index: int) -> np.ndarray:
        """Where the track's centre should be at frame ``index`` (3,) m."""
        return self.centre + self.velocity * max(index - self.last_frame, 0)

    def seen(self, centre: np.ndarray, look: np.ndarray | None, index: int) -> None:
        """Update position, velocity and appearance with this frame's observation."""
        steps = max(index - self.last_frame, 1)
        if np.all(np.isfinite(centre)):
            self.velocity = (1 - VELOCITY_BLEND) * self.velocity + VELOCITY_BLEND * (centre - self.centre) / steps
            self.centre = centre
        if look is not None:
            self.look = look if self.look is None else (1 - LOOK_BLEND) * self.look + LOOK_BLEND * look
        self.last_frame, self.missed = index, 0


@dataclass
class PeopleCounts:
    """Running counts a status message reports: tracks made and retired, segments refused for
    ``max_people``, segments whose detection held no person."""

    created: int = 0
    retired: int = 0
    beyond_max_people: int = 0
    no_person: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counts by name."""
        return {"created": self.created, "retired": self.retired, "beyond_max_people": self.beyond_max_people,
                "no_person": self.no_person}


class PeopleTracker:
    """Tracks up to ``max_people`` people (see the module docstring).

    make_tracker: builds the :class:`BodyTracker` of a new track given its id.
    retire_frames: frames a track may go unseen before it is retired.
    """

    def __init__(self, make_tracker: Callable[[int], BodyTracker], max_people: int = tracker_default("max_people"),
                 retire_frames: int = tracker_default("retire_frames"), first_id: int = 0,
                 counts: PeopleCounts | None = None):
        self.make_tracker, self.max_people, self.retire_frames = make_tracker, int(max_people), int(retire_frames)
        self.tracks: list[Track] = []
        self.counts = counts or PeopleCounts()
        self._next_id = int(first_id)
        self._spare: list[BodyTracker] = []  # trackers of retired or refused tracks, reused (no new scorer)
        self.budget_ms = 0.0  # each person's share of a frame's time (ms, live); 0: the configured search
        self._last_index: int | None = None  # the frame tracked before this one
        self._props: np.ndarray | None = None  # this frame's props (H, W) bool, left out of every fit's depth
        self.live = False  # frames may be dropped between two tracked ones (serve): the gate widens for them

    @property
    def device_name(self) -> str:
        """The OpenCL device of the trackers ("" before the first)."""
        for tracker in [t.tracker for t in self.tracks] + self._spare:
            return tracker.device_name
        return ""

    @property
    def next_id(self) -> int:
        """The id the next new person gets (ids are never reused)."""
        return self._next_id

    def reset(self) -> None:
        """Forget every track (counted as retired; ids go on counting up)."""
        for track in list(self.tracks):
            self._retire(track)

    def personalisation(self) -> list[dict]:
        """Each current track's personalisation state (``--personalize``; empty without)."""
        states = (t.tracker.personalisation() for t in self.tracks)
        return [s for s in states if s is not None]

    def body_of(self, body_id: int) -> SkinnedBody | None:
        """The body the track ``body_id`` is tracked with now (None: no such track)."""
        return next((t.tracker.body for t in self.tracks if t.id == body_id), None)

    def _release(self, tracker: BodyTracker) -> None:
        tracker.new_person()  # a parked tracker keeps nothing of its person (a --personalize fit)
        self._spare.append(tracker)

    def _tracker(self, body_id: int) -> BodyTracker:
        if self._spare:
            tracker = self._spare.pop()
            tracker.body_id = body_id
            tracker.new_person()
            return tracker
        return self.make_tracker(body_id)

    def step(self, frame: Frame, people: Sequence[PersonDetection], labels: np.ndarray | None = None,
             props: np.ndarray | None = None) -> tuple[BodyResult, ...]:
        """The bodies of ``frame``: one per person tracked in it, by id.

        people: each person's segment and 2D joints (segment None: one whole-frame detection);
        labels: (H, W) int the segmentation's person labels (k = ``people[k-1]``), None without;
        props: (H, W) bool pixels of props beside people (:mod:`swarmpose.detect.props`), left out
        of every person's depth, None: none.
        A track whose fit throws restarts (its id stays); the other people go on."""
        self._props = props
        centres = [self._centre(p) for p in people]
        looks = [colour_histogram(frame.color, p.segment.mask) if p.segment is not None else None for p in people]
        results: dict[int, BodyResult] = {}
        assignment = self._associate(frame.index, people, centres, looks)
        self._last_index = frame.index
        for t, o in assignment.pairs:
            track = self.tracks[t]
            body = self._fit(track.tracker, frame, self._others(labels, o, people[o]), people[o].joints)
            if body is not None:
                results[track.id] = body
            track.seen(self._observed_centre(centres[o], body), looks[o], frame.index)
        order = sorted(assignment.lone_observations, key=lambda o: -self._size(people[o]))
        for o in order:
            if len(self.tracks) >= self.max_people and not self._make_room():
                self.counts.beyond_max_people += 1
                continue
            tracker = self._tracker(self._next_id)
            body = self._fit(tracker, frame, self._others(labels, o, people[o]), people[o].joints)
            if body is not None and body.reason == NO_TORSO and None not in (people[o].segment, people[o].joints):
                body = self._retry_start(tracker, frame, people[o])
            if body is None or body.state == "lost":  # no person in its detection: no id for it
                self.counts.no_person += 1
                self._release(tracker)
                continue
            track = Track(self._next_id, tracker, self._observed_centre(centres[o], body), look=looks[o],
                          last_frame=frame.index)
            self._next_id += 1
            self.counts.created += 1
            self.tracks.append(track)
            results[track.id] = body
        for track in list(self.tracks):
            if track.id in results or track.last_frame == frame.index:
                continue
            track.missed += 1
            if track.missed > self.retire_frames:
                self._retire(track)
            elif track.missed <= COAST_FRAMES and track.tracker.previous is not None:
                body = self._fit(track.tracker, frame, self._everyone(labels), None)
                if body is not None and body.state != "lost":
                    results[track.id] = replace(body, reason=COASTING)
                    track.centre, track.velocity = self._fit_centre(body, track.centre), np.zeros(3)
        return tuple(results[i] for i in sorted(results))

    def _fit(self, tracker: BodyTracker, frame: Frame, removed: np.ndarray | None, joints,
             start_min_score: float | None = None) -> BodyResult | None:
        """One person's tracker on ``frame`` with the depth of other people (``removed``, (H, W) bool;
        None: nobody else) and of this frame's props set to no measurement, in one copy; None (and the
        tracker restarted) when it throws. start_min_score: as :meth:`BodyTracker.step` takes it. The
        props do not make the frame one with others removed (its lost test's looser 2D rule is for
        people hidden by people)."""
        tracker.budget_ms = self.budget_ms
        others_removed = removed is not None
        if self._props is not None:
            removed = self._props if removed is None else removed | self._props
        seen = frame if removed is None else _depth_removed(frame, removed)
        try:
            return tracker.step(seen, joints, others_removed=others_removed, start_min_score=start_min_score)
        except Exception as exc:  # one person's failure must not cost the others their fit
            log.warning("frame %d: tracking person %d failed (%s: %s); it restarts", frame.index, tracker.body_id,
                        type(exc).__name__, exc)
            tracker.reset()
            return None

    def _retire(self, track: Track) -> None:
        self.tracks.remove(track)
        self._release(track.tracker)
        self.counts.retired += 1

    def _make_room(self) -> bool:
        """At the cap, retire the longest-unseen track if one is unseen (a person who left makes
        room for one who came); False when every track was seen this frame."""
        waiting = [t for t in self.tracks if t.missed > 0]
        if not waiting:
            return False
        self._retire(max(waiting, key=lambda t: t.missed))
        return True

    @staticmethod
    def _fit_centre(body: BodyResult | None, otherwise: np.ndarray) -> np.ndarray:
        """The mean (3,) m of the fit's finite joints; ``otherwise`` without any."""
        if body is None:
            return otherwise
        joints3d = body.found.joints3d
        joints = joints3d[np.all(np.isfinite(joints3d), axis=1)]
        return joints.mean(axis=0) if len(joints) else otherwise

    def _observed_centre(self, centre: np.ndarray, body: BodyResult | None) -> np.ndarray:
        """The segment's centre, or, without a segment (a whole-frame detection), the fit's; none (NaN:
        the track keeps its centre and velocity) from a fit judged lost."""
        if np.all(np.isfinite(centre)) or (body is not None and body.state == "lost"):
            return centre
        return self._fit_centre(body, centre)

    def _associate(self, index: int, people: Sequence[PersonDetection], centres: list[np.ndarray],
                   looks: list[np.ndarray | None]) -> Assignment:
        """Tracks (rows) paired with this frame's people (columns); see the module docstring."""
        cost = np.full((len(self.tracks), len(people)), NO_PAIR)
        if not people or not self.tracks:
            return assign(cost)
        if all(p.segment is None for p in people):  # a whole-frame detection: the most recent track
            cost[int(np.argmax([t.last_frame for t in self.tracks])), 0] = 0.0
            return assign(cost)
        expected = np.stack([t.expected(index) for t in self.tracks])
        dropped = 0 if self._last_index is None or not self.live else max(index - self._last_index - 1, 0)
        return assign(pair_costs(expected, np.stack(centres), [t.look for t in self.tracks], looks,
                                 APPEARANCE_M, GATE_M + DROPPED_GATE_M * dropped))

    @staticmethod
    def _centre(person: PersonDetection) -> np.ndarray:
        if person.segment is None:
            return np.full(3, np.nan)
        return np.asarray(person.segment.centroid_m, dtype=np.float64)

    @staticmethod
    def _size(person: PersonDetection) -> int:
        return 0 if person.segment is None else int(person.segment.pixels)

    @staticmethod
    def _everyone(labels: np.ndarray | None) -> np.ndarray | None:
        """(H, W) bool: every segmented person's pixels, None when there are none: what is left of a
        person the segmentation did not find (mostly hidden) is background to the others."""
        if labels is None or not np.any(labels):
            return None
        return labels != 0

    def _retry_start(self, tracker: BodyTracker, frame: Frame, person: PersonDetection) -> BodyResult | None:
        """A new person's second start when the first found no torso: on the depth of its segment
        alone (where a weak keypoint lifts, it lifts onto this person), the keypoints down to
        :data:`START_MIN_SCORE` (or the tracker's ``min_score`` if lower)."""
        return self._fit(tracker, frame, ~person.segment.mask, person.joints,
                         min(START_MIN_SCORE, tracker.config.min_score))

    @staticmethod
    def _others(labels: np.ndarray | None, index: int, person: PersonDetection) -> np.ndarray | None:
        """(H, W) bool: the other people's pixels for person ``index`` (0-based), None when there are none."""
        if labels is None or person.segment is None:
            return None
        others = (labels != 0) & (labels != index + 1)
        return others if others.any() else None


def _depth_removed(frame: Frame, where: np.ndarray) -> Frame:
    """A copy of ``frame`` whose depth is 0 (no measurement) ``where`` (H, W) bool is set."""
    return replace(frame, depth=np.where(where, np.float32(0.0), frame.depth))
