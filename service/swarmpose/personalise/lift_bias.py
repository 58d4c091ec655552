"""The lift's own bias on a body (E_B of the shape fit, :mod:`swarmpose.personalise.personalise`):
how much lifting a body's own joints on its own noise-free render lengthens its limbs.

The lift misplaces joints by amounts that depend on the body (a keypoint's depth is the nearest
surface's, pushed back by a constant per joint), so the shape fit compares the observed limb
lengths less :func:`lift_bias` of the candidate body with the candidate's rest lengths.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.gpu.reference import raycast_tiles
from swarmpose.gpu.tile import TileBox
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import observed_depth
from swarmpose.tracking.lift import lift_keypoints, median_depth

LIMB_BONES = tuple((f"{side}_{a}", f"{side}_{b}") for side in ("left", "right")
                   for a, b in (("shoulder", "elbow"), ("elbow", "wrist"), ("knee", "ankle")))
"""Point pairs whose distance is a bone's length, whatever the pose (E_B). Not the hips: a hip
keypoint lifts onto the belly's surface, far in front of the joint, so thighs measured 41-43 cm
against 37.6 true and shoulder-hip 43-45 against 45.7 (female walk), and heights came out
2-2.8 cm tall with them."""


def model_depth(body: SkinnedBody, pose: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """The depth (H, W) float32 m (0: no hit) of ``body`` at ``pose`` (36,), without noise: one ray
    per pixel centre (OpenCV, as :meth:`Intrinsics.project`) cast at the dual-quaternion-skinned mesh."""
    verts = body.pose(np.asarray(pose, float)[None], "dqs")
    w, h = intrinsics.width, intrinsics.height
    return raycast_tiles(verts, np.asarray(body.triangles), TileBox(0, 0, w, h, w, h).rays(intrinsics))[0]


def typical_depth(frame: Frame) -> float | None:
    """The median (m) of ``frame``'s valid depth, the lift's ``typical_depth`` on it (None: no depth)."""
    return median_depth(observed_depth(frame.depth))


def lift_bias(body: SkinnedBody, poses: Sequence[np.ndarray], typical: Sequence[float | None],
              intrinsics: Intrinsics) -> dict[tuple[str, str], float]:
    """How much the lift lengthens each :data:`LIMB_BONES` pair on ``body`` itself (m, median over
    the frames): the body's own joints at each pose (36,), projected without noise and lifted
    (:func:`~swarmpose.tracking.lift.lift_keypoints`) on its own rendered depth
    (:func:`model_depth`), minus the rest length. ``typical``: each frame's :func:`typical_depth`,
    so that the lift's window is the one it used on the observed frame (same pixels, whatever the
    background; None: the frame is skipped). Pairs never lifted are left out."""
    names = sorted({n for bone in LIMB_BONES for n in bone})
    seen: dict[tuple[str, str], list[float]] = {b: [] for b in LIMB_BONES}
    for pose, frame_depth in zip(poses, typical):
        depth = model_depth(body, pose, intrinsics)
        if frame_depth is None or not np.any(depth > 0):
            continue
        points = body.posed_points(np.asarray(pose, float)[None], names)[0]
        uv = intrinsics.project(points)
        lifted = lift_keypoints(depth, intrinsics, {n: (float(x), float(y), 1.0) for n, (x, y) in zip(names, uv)},
                                typical_depth=frame_depth)
        for a, b in LIMB_BONES:
            if np.all(np.isfinite(lifted[a])) and np.all(np.isfinite(lifted[b])):
                seen[(a, b)].append(float(np.linalg.norm(lifted[a] - lifted[b])))
    return {(a, b): float(np.median(v)) - float(np.linalg.norm(body.point(a) - body.point(b)))
            for (a, b), v in seen.items() if v}
