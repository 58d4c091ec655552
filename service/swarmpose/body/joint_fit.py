"""A pose fitted to target positions of a body's named points (inverse kinematics).

Least squares over the root translation and the joint angles (within Table 1's limits), the root
rotation held: minimise Σ |point(h) - target|² + λ² |h - start|² (m², with the angles' part in rad),
from ``start``. The small pull λ to the start keeps the angles that move no target point (twists,
the collar and spine's split) where they were. The Jacobian is taken by forward differences, all
columns posed in one batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLES
from swarmpose.body.skinned import SkinnedBody

PULL_TO_START = 0.01
"""λ: metres of point error that one radian (or metre) away from the start weighs as."""
STEP = 1e-6
"""Forward-difference step of the Jacobian (m or rad)."""
FREE = np.r_[0:3, ANGLES.start:ANGLES.stop]
"""The pose entries fitted: the root translation and the 29 angles."""


def fit_pose_to_points(body: SkinnedBody, start: np.ndarray, names: Sequence[str], targets: np.ndarray,
                       max_evaluations: int = 20) -> np.ndarray:
    """The pose (36,) near ``start`` (36,) whose points ``names`` come nearest ``targets`` (N, 3) m,
    camera frame; the root rotation is ``start``'s; each angle within its limits or, where ``start``'s
    lies outside them, between the limit and ``start``'s. Targets must be finite."""
    targets = np.asarray(targets, dtype=np.float64)
    if targets.shape != (len(names), 3) or not np.all(np.isfinite(targets)):
        raise ValueError(f"targets of shape {targets.shape} (finite, ({len(names)}, 3) expected)")
    start = np.asarray(start, dtype=np.float64)
    x0 = start[FREE]
    # Table 1's limits, widened to the start where it lies outside them (a pose given from elsewhere)
    lo = np.minimum(np.r_[np.full(3, -np.inf), ANGLE_LIMITS[:, 0]], x0)
    hi = np.maximum(np.r_[np.full(3, np.inf), ANGLE_LIMITS[:, 1]], x0)

    def poses(free: np.ndarray) -> np.ndarray:
        out = np.repeat(start[None], len(free), axis=0)
        out[:, FREE] = free
        return out

    def residuals(free: np.ndarray) -> np.ndarray:
        points = body.posed_points(poses(free[None]), names)[0]
        return np.concatenate([(points - targets).ravel(), PULL_TO_START * (free - x0)])

    def jacobian(free: np.ndarray) -> np.ndarray:
        moved = free[None] + STEP * np.eye(len(free))
        points = body.posed_points(poses(np.vstack([free[None], moved])), names)
        d_points = ((points[1:] - points[0]) / STEP).reshape(len(free), -1).T
        return np.vstack([d_points, PULL_TO_START * np.eye(len(free))])

    fit = least_squares(residuals, x0, jac=jacobian, bounds=(lo, hi), method="trf", max_nfev=max_evaluations)
    return poses(fit.x[None])[0]
