"""Centred smoothing of each person's published poses, for recordings (``--smoothing centred``).

A track's per-frame fits scatter about the motion from frame to frame (a detector's keypoints
jump, the swarm stops at a different point of a flat objective). A recording has the frames on
both sides of each one, so it can be smoothed without the lag of a causal filter (the live path's
One-Euro filter). Each joint's published position becomes the value at its time of a straight line
fitted, with Gaussian weights (σ = ``sigma_s``) times the joint's confidence in each frame (plus
:data:`CONFIDENCE_FLOOR`), through that person's positions of it within ±3σ in time: the weighted
mean where the trajectory goes on at both sides, and no lag at its ends. The
published pose is then fitted to those positions (:func:`~swarmpose.body.joint_fit.fit_pose_to_points`,
from the poses' own line fit), so the skeleton keeps the body's bone lengths and the pose, the joints
and a BVH agree. (Joints rather than pose vectors are averaged because an arm whose found angles
swing between two ways of reaching about the same place averages to neither.) A person's trajectory
is cut, and nothing is averaged across
the cut, where the person is lost or missing, where a track (re)starts (state ``init``), where
the root turns by more than :data:`BREAK_TURN_DEG` in one frame (a corrected facing, not motion)
and where the person's body changes (an automatic height or a ``--personalize`` shape locked).
After the backward pass, a refit frame is fitted with the body the backward pass refit it with.
A body whose smoothing fails (logged) is published as found.

As with the One-Euro filter, only what is published is smoothed: the search always starts from
its own last solution, and the result keeps it in ``unfiltered``. Results come 3σ late (0.15 s at
the default σ of 0.05 s), so this is for offline runs only (``track``, ``eval``,
:func:`swarmpose.pipeline.api.track`). Times are the frames' timestamps; where those do not advance,
frames are taken to be 1/30 s apart.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from swarmpose.body.kinematics import root_turn_deg
from swarmpose.body.skeleton import ROOT_QUATERNION
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.pipeline.pose_to_joints import body_at_joints
from swarmpose.tracking.one_euro import DEFAULT_DT_S
from swarmpose.tracking.result import BodyResult, FrameResult

log = logging.getLogger(__name__)

SIGMA_SPAN = 3.0
"""A pose is averaged with the poses within this many σ of it in time."""
CONFIDENCE_FLOOR = 0.05
"""Each joint's line fit weighs a frame by the Gaussian times (the joint's confidence there + this): a
joint the detector and the depth agreed on counts more than one they did not, and a joint with no
confidence anywhere in the window is still smoothed."""
BREAK_TURN_DEG = math.degrees(1.0)
"""A root rotation between two consecutive frames larger than this (degrees: 1 rad) cuts the trajectory."""


def local_linear(values: np.ndarray, offsets_s: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The value (d,) at offset 0 of a weighted straight-line fit through values (n, d) at time offsets
    (n,) s with weights (n,) > 0, per component (locally weighted linear regression): the weighted mean
    where the offsets balance (the middle of a trajectory), and no lag at a trajectory's ends, where
    they do not."""
    w, d = np.asarray(weights, dtype=np.float64), np.asarray(offsets_s, dtype=np.float64)
    x = np.asarray(values, dtype=np.float64)
    total, moment, spread = w.sum(), w @ d, w @ (d * d)
    mean = w @ x / total
    denominator = total * spread - moment * moment
    if denominator > 1e-12 * total * max(spread, 1e-12):
        slope = (total * ((w * d) @ x) - moment * (w @ x)) / denominator
        mean = mean - slope * moment / total
    return mean


def local_linear_pose(poses: np.ndarray, offsets_s: np.ndarray, weights: np.ndarray, centre: int) -> np.ndarray:
    """:func:`local_linear` of poses (n, 36): root quaternions first sign-flipped to agree with
    ``centre``'s, and the result's renormalised."""
    x = np.array(poses, dtype=np.float64)
    q = x[:, ROOT_QUATERNION]
    x[:, ROOT_QUATERNION] = q * np.where(q @ q[centre] < 0, -1.0, 1.0)[:, None]
    out = local_linear(x, offsets_s, weights)
    out[ROOT_QUATERNION] /= np.linalg.norm(out[ROOT_QUATERNION])
    return out


def segment_starts(poses: list[np.ndarray | None], states: list[str], bodies: list[object] | None = None) -> list[int]:
    """Per frame of one person's trajectory (pose (36,) or None where lost or missing; state; the
    body it was fitted with, any object compared by identity), the index of the frame its segment
    starts at (-1 where there is no pose): a segment ends at a missing pose, and a new one starts at
    a state ``init``, after a root turn above :data:`BREAK_TURN_DEG` and where the body changes (a
    height or shape locked: its joints move with no motion)."""
    bodies = bodies if bodies is not None else [None] * len(poses)
    starts, start = [], -1
    for k, (pose, state) in enumerate(zip(poses, states)):
        if pose is None:
            start = -1
        elif (start < 0 or state == "init" or bodies[k] is not bodies[k - 1]
              or root_turn_deg(poses[k - 1], pose) > BREAK_TURN_DEG):
            start = k
        starts.append(start)
    return starts


class CentredSmoother:
    """Holds results ``SIGMA_SPAN`` σ and hands them on with each person's pose smoothed (module
    doc). Use: :meth:`note_bodies` with every result as the pipeline makes it (the bodies and camera
    its poses were fitted with), :meth:`add` each result in order, :meth:`finish` at the end,
    :meth:`release` when the run fails. sigma_s: the Gaussian's σ in seconds (> 0)."""

    def __init__(self, sigma_s: float):
        if not sigma_s > 0:
            raise ValueError(f"a centred smoothing sigma of {sigma_s} s; it must be above 0")
        self.sigma_s, self.span_s = float(sigma_s), SIGMA_SPAN * float(sigma_s)
        self.held: list[tuple[float, FrameResult]] = []  # not yet handed on, with their times
        self.past: list[tuple[float, FrameResult]] = []  # handed on, still within the span of the held
        self.fitted_with: dict[tuple[int, int], tuple[SkinnedBody, Intrinsics]] = {}
        self._clock: tuple[int, float] | None = None  # the last (timestamp_ns, time s)

    def note_bodies(self, result: FrameResult, body_of: Callable[[int], SkinnedBody | None],
                    intrinsics: Intrinsics | None) -> None:
        """Keep, per body of ``result``, the body (``body_of(id)``, as the tracker has it now) and
        camera its pose was fitted with."""
        for body in result.bodies:
            skinned = body_of(body.id) if body.pose is not None else None
            if skinned is not None and intrinsics is not None:
                self.fitted_with[(result.index, body.id)] = (skinned, intrinsics)

    def note_refits(self, bodies: dict[tuple[int, int], SkinnedBody], intrinsics: Intrinsics | None) -> None:
        """Keep the bodies the backward pass refit frames with, by (frame index, id), in place of
        those :meth:`note_bodies` kept for them."""
        if intrinsics is not None:
            self.fitted_with.update({key: (body, intrinsics) for key, body in bodies.items()})

    def add(self, result: FrameResult) -> list[FrameResult]:
        """Hold ``result``; the held results now ``SIGMA_SPAN`` σ older than it, smoothed."""
        self.held.append((self._time_s(result), result))
        newest = self.held[-1][0]
        ready = sum(1 for t, _ in self.held if newest - t >= self.span_s)
        return self._hand_on(ready)

    def finish(self) -> list[FrameResult]:
        """Every result still held, smoothed with the frames there are."""
        return self._hand_on(len(self.held))

    def release(self) -> list[FrameResult]:
        """Every result still held, as found (the run failed)."""
        out = [r for _, r in self.held]
        self.held, self.past = [], []
        self.fitted_with.clear()
        return out

    def _time_s(self, result: FrameResult) -> float:
        """The result's time on a clock that advances by its timestamps, or by 1/30 s where they do not."""
        if self._clock is None:
            time_s = 0.0
        else:
            stamp, last = self._clock
            step = (result.timestamp_ns - stamp) / 1e9
            time_s = last + (step if step > 0 else DEFAULT_DT_S)
        self._clock = (result.timestamp_ns, time_s)
        return time_s

    def _hand_on(self, count: int) -> list[FrameResult]:
        """The first ``count`` held results, smoothed; they become the past of those still held."""
        window = self.past + self.held
        first = len(self.past)
        out = [self._smoothed(window, first + k) for k in range(count)]
        self.past, self.held = window[:first + count], self.held[count:]
        horizon = (self.held[0][0] if self.held else window[-1][0]) - self.span_s  # what the next ones may need
        gone = [r for t, r in self.past if t < horizon]
        self.past = [(t, r) for t, r in self.past if t >= horizon]
        for r in gone:
            for body in r.bodies:
                self.fitted_with.pop((r.index, body.id), None)
        return out

    def _smoothed(self, window: list[tuple[float, FrameResult]], k: int) -> FrameResult:
        """Result ``k`` of ``window`` with every body's pose smoothed over ``window`` (and the time it took,
        ms, as its ``timings_ms["smoothing"]``)."""
        t0 = time.perf_counter()
        time_s, result = window[k]
        bodies = tuple(self._smoothed_body(window, k, time_s, result.index, body) for body in result.bodies)
        if all(a is b for a, b in zip(bodies, result.bodies)):
            return result
        return replace(result, bodies=bodies,
                       timings_ms={**result.timings_ms, "smoothing": 1000 * (time.perf_counter() - t0)})

    def _smoothed_body(self, window: list[tuple[float, FrameResult]], k: int, time_s: float, index: int,
                       body: BodyResult) -> BodyResult:
        fitted = self.fitted_with.get((index, body.id))
        if body.pose is None or body.state == "lost" or fitted is None:
            return body
        mine = [next((b for b in r.bodies if b.id == body.id), None) for _, r in window]
        poses = [None if b is None or b.state == "lost" or b.pose is None else b.pose for b in mine]
        bodies = [self.fitted_with.get((r.index, body.id), (None,))[0] for _, r in window]
        starts = segment_starts(poses, [b.state if b is not None else "lost" for b in mine], bodies)
        near = [j for j in range(len(window)) if starts[j] == starts[k] and abs(window[j][0] - time_s) <= self.span_s]
        if len(near) < 2:
            return body
        offsets = np.array([window[j][0] for j in near]) - time_s
        weights = np.exp(-0.5 * (offsets / self.sigma_s) ** 2)
        start = local_linear_pose(np.stack([poses[j] for j in near]), offsets, weights, near.index(k))
        positions = np.stack([mine[j].joints3d for j in near])  # (n, J, 3)
        trust = np.nan_to_num(np.stack([mine[j].confidence for j in near])) + CONFIDENCE_FLOOR  # (n, J)
        joints = np.stack([local_linear(positions[:, q], offsets, weights * trust[:, q])
                           for q in range(positions.shape[1])])
        skinned, intrinsics = fitted
        try:
            return body_at_joints(body, skinned, intrinsics, start, joints)
        except Exception as exc:  # that body is published as found; the run goes on
            log.warning("centred smoothing of person %d at frame %d failed (%s: %s); published as found",
                        body.id, index, type(exc).__name__, exc)
            return body
