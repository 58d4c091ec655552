"""Several independent tracks of the same frames, their joints averaged (``--ensemble N``).

A particle swarm stops at one of the objective's minima, and which one it finds for a joint the
depth and the detector do not pin down (an arm seen side on, behind the torso, under a wrong
keypoint) depends on its random draws: the same recording tracked with another PSO seed puts such
a joint elsewhere, for whole stretches of frames. :class:`EnsemblePipeline` runs ``N`` pipelines
with seeds ``seed``, ``seed + 1``, ... over the same frames in lockstep, each with its own
detector feedback, people, ids and bodies, and publishes the first one's people with each joint
the mean of where the ``N`` tracks put it, each weighed by that track's confidence in the joint
(plus :data:`~swarmpose.pipeline.centred_smoothing.CONFIDENCE_FLOOR`); the pose is then fitted to
those joints (:func:`~swarmpose.pipeline.pose_to_joints.body_at_joints`, from the first track's
pose), so the skeleton keeps the body's bone lengths. A mean rather than the track with the
lowest objective, because the objective does not reliably tell the right track from a wrong one.

The first pipeline decides who is there: the other tracks' bodies are assigned one to one to its
people by the least total mean joint distance (scipy's ``linear_sum_assignment``; a pair farther
apart than :data:`MATCH_M`, or turned the other way, is no pair and takes no one's place in the
assignment); a person only the others found is left out, and a person the others did not find is
published as the first track has it. The members
share the detector (each calls it on its own crops; a BlazePose detector's regions of the last
frame, :mod:`swarmpose.detect.regions`, are shared too, so a member may crop another's) and only the first one keeps
the world frame (``--floor``). Each track searches on from its own
solution: the average is published, never fed back. Each frame costs ``N`` times the detection
and tracking; nothing is published late, so :class:`~swarmpose.pipeline.api.Tracker` may use it
frame by frame; ``serve`` and ``replay`` (whose worker runs detection and tracking in two
threads) refuse it, and so does the backward pass, whose refits follow one track.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.pipeline.centred_smoothing import CONFIDENCE_FLOOR
from swarmpose.pipeline.pose_to_joints import body_at_joints
from swarmpose.pipeline.step import FramePipeline
from swarmpose.sim.evaluate import torso_facing
from swarmpose.sim.people_metrics import mean_joint_distance
from swarmpose.sources.base import Frame, SkippedFrame
from swarmpose.tracking.result import BodyResult, FrameResult

log = logging.getLogger(__name__)

MATCH_M = 0.5
"""Another track's body farther than this (mean joint distance, m) from every person of the first
track's is nobody's."""


def mean_joint_distances(a: Sequence[BodyResult], b: Sequence[BodyResult]) -> np.ndarray:
    """(len(a), len(b)) :func:`~swarmpose.sim.people_metrics.mean_joint_distance` (m) of each pair's
    joints (inf where they share none)."""
    out = np.array([[mean_joint_distance(x.joints3d, y.joints3d) for y in b] for x in a], dtype=np.float64)
    return np.where(np.isfinite(out), out, np.inf).reshape(len(a), len(b))


def same_facing(a: BodyResult, b: BodyResult) -> bool:
    """Whether ``a`` and ``b`` face the same way (their :func:`~swarmpose.sim.evaluate.torso_facing`
    less than 90 degrees apart: a mirrored facing and left and right swapped both turn it round);
    True where either lacks the torso joints to tell."""
    dot = float(np.sum(torso_facing(np.stack([a.joints3d, b.joints3d])).prod(axis=0)))
    return not np.isfinite(dot) or dot > 0


def matched_bodies(first: Sequence[BodyResult], other: Sequence[BodyResult]) -> dict[int, BodyResult]:
    """Which of ``other`` counts for each of ``first`` (index in ``first`` -> body): one to one, by
    the least total mean joint distance among the pairs within :data:`MATCH_M`, never a body facing
    the other way (:func:`same_facing`: a track locked in the mirrored facing, or with left and right
    swapped, lies within reach of the person, and its average would pull both shoulders to the
    middle)."""
    if not first or not other:
        return {}
    cost = mean_joint_distances(first, other)
    pairable = cost <= MATCH_M  # inf (no joint shared) is never pairable
    pairable &= np.array([[same_facing(a, b) for b in other] for a in first], dtype=bool)
    rows, cols = linear_sum_assignment(np.where(pairable, cost, 1e6))  # an unpairable body takes no one's place
    return {int(i): other[j] for i, j in zip(rows, cols) if pairable[i, j]}


def fused_joints(bodies: Sequence[BodyResult]) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's mean (J, 3) m over ``bodies``, weighed by each body's confidence in it plus
    ``CONFIDENCE_FLOOR`` (a body without the joint left out; NaN where none has it), and the mean
    confidence (J,) of the bodies that have the joint (the first body's where none has it)."""
    joints = np.stack([np.asarray(b.joints3d, float) for b in bodies])  # (N, J, 3)
    scores = np.nan_to_num(np.stack([np.asarray(b.confidence, float) for b in bodies]))  # (N, J)
    have = np.all(np.isfinite(joints), axis=2)  # (N, J)
    trust = np.where(have, scores + CONFIDENCE_FLOOR, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.einsum("nj,njk->jk", trust, np.nan_to_num(joints)) / trust.sum(axis=0)[:, None]
        confidence = np.where(have.any(axis=0), (scores * have).sum(axis=0) / have.sum(axis=0), scores[0])
    mean[~have.any(axis=0)] = np.nan
    return mean, confidence


class EnsemblePipeline:
    """``members`` (two or more :class:`FramePipeline`, built alike but for the PSO seed) tracking the
    same frames; :meth:`process` gives the first one's result with each person's joints and pose
    averaged over the members (module doc). Offers what :func:`swarmpose.pipeline.run.results` and
    :class:`~swarmpose.pipeline.api.Tracker` use of a pipeline."""

    backward = 0  # the backward pass refits one track: refused with an ensemble (TrackerConfig)

    def __init__(self, members: Sequence[FramePipeline]):
        if len(members) < 2:
            raise ValueError(f"an ensemble of {len(members)} pipelines; it needs at least 2")
        self.members = list(members)
        self.first = self.members[0]
        self.on_step = None

    @property
    def centred_sigma_s(self) -> float:
        return self.first.centred_sigma_s

    @property
    def intrinsics(self) -> Intrinsics | None:
        return self.first.intrinsics

    @property
    def device_name(self) -> str:
        return self.first.device_name

    @property
    def personalise_frames(self) -> int:
        return self.first.personalise_frames

    @property
    def personalisation(self) -> dict | None:
        return self.first.personalisation

    @property
    def world(self):
        return self.first.world

    def body_of(self, body_id: int) -> SkinnedBody | None:
        """The body the first track fits person ``body_id`` with (the published poses are of it)."""
        return self.first.body_of(body_id)

    def process(self, item: Frame | SkippedFrame) -> FrameResult:
        """Every member's result of ``item``, fused into the first one's (module doc)."""
        results = [member.process(item) for member in self.members]
        t0 = time.perf_counter()
        fused = self.fuse(results)
        ms = 1000 * (time.perf_counter() - t0)
        timings = dict(fused.timings_ms)
        timings["total"] = sum(r.timings_ms.get("total", 0.0) for r in results) + ms
        timings["ensemble"] = ms
        return replace(fused, timings_ms=timings)

    def fuse(self, results: Sequence[FrameResult]) -> FrameResult:
        """The first of ``results`` (one per member, the same frame) with each tracked body's joints the
        confidence-weighted mean over the members' bodies matched to it, and its pose fitted to them."""
        first, others = results[0], results[1:]
        tracked = [k for k, b in enumerate(first.bodies) if b.state != "lost" and b.pose is not None]
        if not tracked or first.skipped:
            return first
        mine = [first.bodies[k] for k in tracked]
        votes: list[list[BodyResult]] = [[b] for b in mine]
        for result in others:
            theirs = [b for b in result.bodies if b.state != "lost" and b.pose is not None]
            for i, body in matched_bodies(mine, theirs).items():
                votes[i].append(body)
        bodies = list(first.bodies)
        for k, vote in zip(tracked, votes):
            if len(vote) > 1:
                bodies[k] = self._averaged(first.index, first.bodies[k], vote)
        return replace(first, bodies=tuple(bodies))

    def _averaged(self, index: int, body: BodyResult, votes: Sequence[BodyResult]) -> BodyResult:
        """``body`` moved to the mean of ``votes``' joints; as it is where that fails (logged)."""
        skinned, intrinsics = self.first.body_of(body.id), self.first.intrinsics
        if skinned is None or intrinsics is None:
            return body
        joints, confidence = fused_joints(votes)
        if not np.all(np.isfinite(joints)):  # a joint no track has: nothing to fit the pose to
            return body
        try:
            averaged = body_at_joints(body, skinned, intrinsics, body.pose, joints)
        except Exception as exc:  # that body is published as the first track found it; the run goes on
            log.warning("the ensemble's average of person %d at frame %d failed (%s: %s); published as the first "
                        "track found it", body.id, index, type(exc).__name__, exc)
            return body
        return replace(averaged, confidence=confidence)

    def reset(self) -> None:
        """Forget every member's tracks."""
        for member in self.members:
            member.reset()


def ensemble_of(make: Callable[[int], FramePipeline], seed: int, size: int) -> FramePipeline | EnsemblePipeline:
    """``make(seed)`` alone when ``size`` is 1, else an :class:`EnsemblePipeline` of ``make(seed + k)``
    for k = 0 .. size - 1."""
    if size <= 1:
        return make(seed)
    return EnsemblePipeline([make(seed + k) for k in range(size)])
