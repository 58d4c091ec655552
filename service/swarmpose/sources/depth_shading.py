"""A grey image made from a depth image, for 2D pose networks on depth-only cameras.

:func:`shaded_normals` lights the surface the depth describes like a plaster statue: each
pixel's normal (from the back-projected point map's neighbours) is shaded by a light at the
camera, tilted up and to the left so that limbs in front of the torso stand out by their
edges; pixels without depth stay black. RGB networks trained on photos (MoveNet, BlazePose)
find people in such images.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ShapeError

LIGHT = np.array([-0.35, -0.45, -1.0]) / np.linalg.norm([-0.35, -0.45, -1.0])
"""Direction towards the light in the camera frame (x right, y down, z forward): from the camera, up-left."""

AMBIENT = 0.15
"""Brightness of a surface facing away from the light (0..1)."""

MAX_STEP_M = 0.05
"""Neighbours farther apart in depth than this are a silhouette edge, not one surface."""


def shaded_normals(depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) uint8 grey image of ``depth`` (H, W) m lit by :data:`LIGHT`; black where depth is missing.

    Normals are the cross product of the central differences along the rows and columns;
    across a depth step larger than :data:`MAX_STEP_M` the one-sided difference on the
    nearer side is used, so silhouettes do not smear.
    """
    depth = np.asarray(depth, dtype=np.float64)
    if depth.ndim != 2:
        raise ShapeError(f"depth must be (H, W), got {depth.shape}")
    p = intrinsics.point_map(depth)
    valid = np.isfinite(p[..., 2])

    def difference(axis: int) -> np.ndarray:
        ahead = np.roll(p, -1, axis=axis)
        behind = np.roll(p, 1, axis=axis)
        forward, backward = ahead - p, p - behind
        f_ok = np.isfinite(forward[..., 2]) & (np.abs(forward[..., 2]) < MAX_STEP_M)
        b_ok = np.isfinite(backward[..., 2]) & (np.abs(backward[..., 2]) < MAX_STEP_M)
        edge = [slice(None)] * 2
        edge[axis] = -1
        f_ok[tuple(edge)] = False
        edge[axis] = 0
        b_ok[tuple(edge)] = False
        both = f_ok & b_ok
        out = np.where(both[..., None], 0.5 * (forward + backward),
                       np.where(f_ok[..., None], forward, np.where(b_ok[..., None], backward, np.nan)))
        return out

    normal = np.cross(difference(1), difference(0))
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = normal / length
    # make every normal face the camera (z < 0 in a frame with z forward)
    normal = np.where(normal[..., 2:3] > 0, -normal, normal)
    light = np.clip(np.nan_to_num(normal @ LIGHT, nan=1.0), 0.0, 1.0)
    grey = np.where(valid, AMBIENT + (1.0 - AMBIENT) * light, 0.0)
    return np.repeat(np.round(255 * grey).astype(np.uint8)[..., None], 3, axis=-1)
