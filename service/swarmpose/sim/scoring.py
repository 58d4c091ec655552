"""Score frame messages against a sequence's ground truth as they are published (Δ, A(t);
with several true people also per-person Δ, identity switches, MOTA and IDF1)."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.world import transform_points
from swarmpose.sim.evaluate import summarise_frames
from swarmpose.sim.people_metrics import TruePerson, score_people
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import GroundTruth


def body_joints(body: dict) -> np.ndarray:
    """(J, 3) m joints of one body entry of a frame message, ``EVAL_JOINTS`` order, NaN where unknown."""
    joints = np.full((len(EVAL_JOINTS), 3), np.nan)
    named = body.get("joints") or {}
    for k, name in enumerate(EVAL_JOINTS):
        p = (named.get(name) or {}).get("position_m")
        if p is not None:
            joints[k] = p
    return joints


class ScoreSink:
    """Keeps the 3D joints of every body of every frame message that has ground truth.

    ``summary()``: :func:`swarmpose.sim.evaluate.summarise` over the frames the run went through
    (a frame without a body or without a joint counts as a miss); the estimate of a frame is
    the body matched to the (first) true person (see :meth:`estimates`), so a second body
    found elsewhere does not replace it. ``people_summary()``: with several true people, :func:`score_people`.
    """

    def __init__(self, ground_truth: GroundTruth):
        self.ground_truth = ground_truth
        self.bodies: dict[int, dict[int, np.ndarray]] = {}
        self._lost: dict[int, np.ndarray | None] = {}

    def frame(self, message: dict, frame: Frame | None) -> None:
        index = message["frame"]
        try:
            self.ground_truth.row(index)
        except KeyError:  # a frame the sequence has no ground truth for
            return
        back = None  # ground truth is in the camera frame: world coordinates go back there
        if message.get("coordinates") == "world" and message.get("camera_to_world") is not None:
            back = np.linalg.inv(np.asarray(message["camera_to_world"], dtype=np.float64))

        def joints_of(body: dict) -> np.ndarray:
            return body_joints(body) if back is None else transform_points(back, body_joints(body))

        self.bodies[index] = {int(b.get("id", k)): joints_of(b) for k, b in enumerate(message["bodies"])
                              if b.get("state") != "lost"}
        lost = [joints_of(b) for b in message["bodies"] if b.get("state") == "lost"]
        self._lost[index] = lost[0] if lost else None

    def estimates(self) -> dict[int, np.ndarray]:
        """Frame -> (J, 3) m estimate of the (first) true person: the body that the tracking
        metrics' matching (:func:`score_people`: nearest within 0.5 m, kept while it stays so;
        among all the true people where there are several) gives it; with one body per frame,
        that body even when lost (a miss scored as it is)."""
        if self.several:  # matched among all the true people, so that person 1 cannot take another's body
            first = self.ground_truth.people[self.ground_truth.row(min(self.bodies))][0].id
            matched = self.people_summary()["matched"].get(first, {})
        else:
            truth = {f: [TruePerson(1, self.ground_truth.joints3d[self.ground_truth.row(f)])] for f in self.bodies}
            matched = score_people(truth, self.bodies)["matched"].get(1, {}) if self.bodies else {}
        out, several = {}, self.several
        for f, bodies in self.bodies.items():
            if f in matched:
                out[f] = bodies[matched[f]]
            elif several:  # another person's body is no estimate of this one
                out[f] = np.full((len(EVAL_JOINTS), 3), np.nan)
            elif len(bodies) == 1:
                out[f] = next(iter(bodies.values()))
            elif not bodies and self._lost.get(f) is not None:
                out[f] = self._lost[f]
            else:
                out[f] = np.full((len(EVAL_JOINTS), 3), np.nan)
        return out

    @property
    def several(self) -> bool:
        """Whether the ground truth holds several people."""
        return any(len(people) > 1 for people in getattr(self.ground_truth, "people", ()))

    def people_summary(self) -> dict:
        """:func:`~swarmpose.sim.people_metrics.score_people` over the frames seen (several true people)."""
        truth = {}
        for index in sorted(self.bodies):
            people = self.ground_truth.people[self.ground_truth.row(index)]
            truth[index] = [TruePerson(p.id, p.joints3d, p.visible) for p in people]
        return score_people(truth, self.bodies)

    def status(self, message: dict) -> None:
        """Status messages carry nothing to score."""

    def close(self) -> None:
        """Nothing to release."""

    def summary(self) -> dict:
        """Δ (``mpjpe_mm``), ``A``, ``coverage``, ``frames``, ``per_joint_mm`` of the frames seen."""
        estimates = self.estimates()
        return summarise_frames(self.ground_truth, sorted(estimates), estimates)
