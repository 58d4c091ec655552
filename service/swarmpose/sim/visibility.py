"""Which true joints the camera sees: the split of an error into visible and hidden joints.

A joint lies inside its limb, so the surface the camera sees at its image point is always a little
in front of it (a limb's radius, a hip's depth in the pelvis). A joint is *hidden* when the observed
depth around its true image point lies more than :data:`HIDDEN_MARGIN_M` in front of it (the torso
before the far arm of a side view, a forearm crossing the chest, another person or a prop), when it
projects outside the image, or when no depth is measured around it; otherwise it is *visible*. This
is what Azure Kinect Body Tracking's confidence levels tell apart ("occluded" against "medium"), and
it needs only what a recording has: the depth and the true joints, so it applies to real data too.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.tracking.lift import sample_surface_depth

HIDDEN_MARGIN_M = 0.15
"""A joint is hidden when the depth at its image point is this much or more in front of it: more than a
limb's radius or a hip joint's depth in the pelvis (5-12 cm), less than a torso's width (30 cm)."""
WINDOW_PX = 2
"""The depth around a joint's image point: the median of the measured pixels within this many pixels."""


def hidden_joints(depth: np.ndarray, intrinsics: Intrinsics, joints: np.ndarray,
                  margin_m: float = HIDDEN_MARGIN_M) -> np.ndarray:
    """(J,) bool, True where joint j of ``joints`` (J, 3) m (camera frame) is hidden in ``depth`` (H, W) m
    (0 or NaN: not measured) taken with ``intrinsics`` (module doc). A joint that is not finite counts as
    hidden (nothing shows it)."""
    depth = np.asarray(depth, dtype=np.float64)
    joints = np.asarray(joints, dtype=np.float64)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise ConfigError(f"depth is {depth.shape[1]}x{depth.shape[0]}, the camera is "
                          f"{intrinsics.width}x{intrinsics.height}; pass the frame's own intrinsics")
    if joints.ndim != 2 or joints.shape[1] != 3:
        raise ConfigError(f"joints must be (J, 3) metres, got {joints.shape}")
    hidden = np.ones(len(joints), dtype=bool)
    placed = np.flatnonzero(np.all(np.isfinite(joints), axis=1) & (joints[:, 2] > 0))
    for k, (u, v) in zip(placed, intrinsics.project(joints[placed])):
        seen = sample_surface_depth(depth, u, v, 2 * WINDOW_PX + 1, cluster_m=np.inf)  # all measured pixels
        if np.isfinite(seen):  # NaN: outside the image, or nothing measured there
            hidden[k] = seen < joints[k, 2] - margin_m
    return hidden


def split_errors_mm(errors_mm: np.ndarray, hidden: np.ndarray) -> dict[str, float | None]:
    """Mean joint error (mm) over the visible and over the hidden true joints, and the hidden share.

    errors_mm: (F, J) per-joint errors (:func:`swarmpose.sim.evaluate.joint_errors`; NaN: not
    estimated, left out); hidden: (F, J) bool (:func:`hidden_joints` per frame). Returns
    ``visible_mm`` and ``hidden_mm`` (None where no such joint was estimated) and ``hidden_share``
    (of the estimated joints, 0..1; None: none estimated)."""
    error, hidden = np.asarray(errors_mm, float), np.asarray(hidden, bool)
    if hidden.shape != error.shape:
        raise ConfigError(f"errors {error.shape} and hidden {hidden.shape} must both be (F, J)")
    known = np.isfinite(error)

    def mean(mask: np.ndarray) -> float | None:
        return float(error[mask].mean()) if mask.any() else None

    return {"visible_mm": mean(known & ~hidden), "hidden_mm": mean(known & hidden),
            "hidden_share": float(hidden[known].mean()) if known.any() else None}
