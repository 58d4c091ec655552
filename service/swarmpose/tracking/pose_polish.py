"""A local polish of one pose on one frame's objective: a batched (1+λ) evolution strategy.

The tracker's per-frame search (a PSO spread around the previous pose at its frame budget) stops
short of the frame's minimum; this polish takes the pose further down the same objective. Each
round moves a random quarter of the movable coordinates of λ copies of the current pose by
Gaussian steps (root translation m, root quaternion and joint angles rad), keeps the best copy if
it beats the current pose, and widens the steps after a success and narrows them after a failure. Poses stay within
the angle limits, quaternions unit length; the result is never worse than the start.

The tracker (``polish`` setting) moves everything but the arms (:data:`WITHOUT_ARMS`): a polished
side-on arm follows the detector's wrong keypoints more closely.
On a young track's frames (ages 1-4, while the start's facings are re-checked) it polishes the best
particle of each facing the swarm holds (:func:`polish_facings`: the track's, and a turned one that a
re-check brought) before they compete, so that a track started mirrored does not sit, polished, too
deep for an unpolished re-check to replace it. On a settled track it polishes the chosen pose only
(:func:`polish_solution`), so that a later re-check's mirrored facing, polished, cannot flip a
settled track.
The shape fit's pose step runs without it; its last stage
(:mod:`~swarmpose.personalise.own_pose_search`) polishes each candidate's key frames.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from swarmpose.body.kinematics import root_turn_deg
from swarmpose.tracking.budget import POLISH_CANDIDATES
from swarmpose.tracking.pso import PsoResult
from swarmpose.tracking.search import LIMB_COLUMNS, pose_bounds, renormalise

STEP_ROOT_M = 0.015
"""The root translation's step (m, one standard deviation) at the start."""
STEP_ANGLE_RAD = 0.06
"""The joint angles' step (rad) at the start; the root quaternion's entries take half."""
SHARE_MOVED = 0.25
"""Share of the movable coordinates one copy moves (sparse steps find one limb's moves)."""

WITHOUT_ARMS = np.ones(36, dtype=bool)
"""(36,) the pose's coordinates but both arms' (collar, shoulder, elbow) angles."""
WITHOUT_ARMS[np.concatenate(LIMB_COLUMNS[:2])] = False


def polish_pose(objective: Callable[[np.ndarray], np.ndarray], pose: np.ndarray, iterations: int,
                rng: np.random.Generator, movable: np.ndarray | None = None,
                candidates: int = POLISH_CANDIDATES) -> tuple[np.ndarray, float]:
    """The best pose (36,) found from ``pose`` (36,) and its value: ``iterations`` rounds of
    ``candidates`` poses each, scored in one batch by ``objective`` ((P, 36) -> (P,)).
    ``movable``: (36,) bool, the coordinates the search may move (None: all). With no
    ``iterations`` the pose comes back as it is, its value NaN (nothing scored)."""
    if iterations <= 0:
        return np.asarray(pose, float), float("nan")
    lo, hi = pose_bounds()
    best = np.asarray(pose, float).copy()
    best_value = float(np.asarray(objective(best[None]), float)[0])
    best_value = best_value if np.isfinite(best_value) else np.inf  # a NaN start: any finite copy beats it
    step = np.full(best.shape, STEP_ANGLE_RAD)
    step[:3], step[3:7] = STEP_ROOT_M, STEP_ANGLE_RAD / 2
    scale = 1.0
    for _ in range(iterations):
        moved = rng.random((candidates, best.size)) < SHARE_MOVED
        if movable is not None:
            moved &= movable
        trial = best + moved * rng.normal(0.0, 1.0, (candidates, best.size)) * step * scale
        trial = renormalise(np.clip(trial, lo, hi))
        values = np.asarray(objective(trial), float)
        values = np.where(np.isfinite(values), values, np.inf)
        k = int(np.argmin(values))
        if values[k] < best_value:
            best, best_value = trial[k].copy(), float(values[k])
            scale = min(scale * 1.2, 2.0)
        else:
            scale *= 0.8
    return best, best_value


def polish_facings(objective: Callable[[np.ndarray], np.ndarray], result: PsoResult, previous: np.ndarray,
                   iterations: int, rng: np.random.Generator, movable: np.ndarray | None = None,
                   turn_deg: float = 90.0) -> PsoResult:
    """The search's ``result`` with the best particle of each facing polished: the best of those
    whose root turned at most ``turn_deg`` from ``previous`` (36,), the track's facing, and the best
    of the rest, if any (a re-check's or the start's other facing); ``best`` and ``value`` chosen
    again among the polished. Polishing only the winner left an unpolished other facing to compete
    with a track polished frame after frame: a track started in the mirrored facing of a person seen
    from behind then sat too deep for the re-checks to replace it. No ``iterations``: ``result``."""
    if iterations <= 0:
        return result
    poses, values = result.personal_bests.copy(), result.personal_values.copy()
    turned = np.asarray(root_turn_deg(previous, poses)) > turn_deg
    for k in (result.best_among(~turned), result.best_among(turned)):
        if k is not None:
            poses[k], values[k] = polish_pose(objective, poses[k], iterations, rng, movable)
    g = int(np.argmin(values))
    return replace(result, best=poses[g].copy(), value=float(values[g]), personal_bests=poses, personal_values=values)


def polish_solution(objective: Callable[[np.ndarray], np.ndarray], result: PsoResult, previous: np.ndarray | None,
                    iterations: int, rng: np.random.Generator, duel: bool,
                    hold: Callable[[PsoResult], np.ndarray], turn_deg: float = 90.0) -> np.ndarray:
    """A frame's solution (36,) from its search's ``result``, polished (the tracker's ``polish``).

    previous: the track's last pose (None on a track's first frame: the best, polished); hold:
    the tracker's choice between the track's facing and a turned challenger
    (:meth:`~swarmpose.tracking.body_tracker.BodyTracker._hold_facing`). duel: each facing's best
    polished before ``hold`` chooses (:func:`polish_facings`: a young track, whose start's facings
    are re-checked on equal terms); else ``hold`` chooses first and its pick is polished: a
    settled track's polished pose meets a turned challenger with the advantage of its frames, so a
    re-check's mirrored facing cannot flip a settled track by being polished too."""
    if duel and previous is not None:
        return hold(polish_facings(objective, result, previous, iterations, rng, WITHOUT_ARMS, turn_deg))
    best = result.best if previous is None else hold(result)
    return polish_pose(objective, best, iterations, rng, WITHOUT_ARMS)[0]
