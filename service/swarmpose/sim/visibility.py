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
    finite = np.all(np.isfinite(joints), axis=1) & (joints[:, 2] > 0)
    if not finite.any():
        return hidden
    uv = np.rint(intrinsics.project(joints[finite])).astype(np.int64)
    h, w = depth.shape
    for k, (u, v), z in zip(np.flatnonzero(finite), uv, joints[finite, 2]):
        if not (0 <= u < w and 0 <= v < h):
            continue
        patch = depth[max(v - WINDOW_PX, 0):v + WINDOW_PX + 1, max(u - WINDOW_PX, 0):u + WINDOW_PX + 1]
        seen = patch[np.isfinite(patch) & (patch > 0)]
        if seen.size:
            hidden[k] = float(np.median(seen)) < z - margin_m
    return hidden


def split_errors_mm(estimates: np.ndarray, truth: np.ndarray, hidden: np.ndarray) -> dict[str, float | None]:
    """Mean joint error (mm) over the visible and over the hidden true joints, and the hidden share.

    estimates, truth: (F, J, 3) m (NaN rows: a lost frame, left out); hidden: (F, J) bool
    (:func:`hidden_joints` per frame). Returns ``visible_mm`` and ``hidden_mm`` (None where no such
    joint was estimated) and ``hidden_share`` (of the estimated joints, 0..1; None: none estimated)."""
    estimates, truth, hidden = np.asarray(estimates, float), np.asarray(truth, float), np.asarray(hidden, bool)
    if estimates.shape != truth.shape or hidden.shape != truth.shape[:2]:
        raise ConfigError(f"estimates {estimates.shape}, truth {truth.shape} and hidden {hidden.shape} must be "
                          "(F, J, 3), (F, J, 3) and (F, J)")
    error = np.linalg.norm(estimates - truth, axis=-1)
    known = np.isfinite(error)

    def mean(mask: np.ndarray) -> float | None:
        return float(1000 * error[mask].mean()) if mask.any() else None

    return {"visible_mm": mean(known & ~hidden), "hidden_mm": mean(known & hidden),
            "hidden_share": float(hidden[known].mean()) if known.any() else None}
