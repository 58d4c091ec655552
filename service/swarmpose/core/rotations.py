"""Rotations in pure numpy: quaternions (``w, x, y, z``), rotation matrices (acting on column
vectors) and rotation vectors (axis times angle, rad).

Written out here rather than taken from ``scipy.spatial.transform``: importing that package loads
all of ``scipy.spatial`` (k-d trees, Qhull, sparse matrices), about half a second of every start of
the service, for a few lines of arithmetic. The tests check these against scipy's ``Rotation``.
"""

from __future__ import annotations

import numpy as np


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) wxyz -> rotation matrices (..., 3, 3). Normalises first."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) wxyz with w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    tr = np.trace(m, axis1=-2, axis2=-1)
    # Four candidate formulas; pick the numerically largest denominator per matrix.
    cand = np.stack([
        tr,
        2 * m[..., 0, 0] - tr,
        2 * m[..., 1, 1] - tr,
        2 * m[..., 2, 2] - tr,
    ], -1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    s = np.sqrt(np.maximum(1.0 + np.max(cand, axis=-1), 1e-300)) * 2  # 4 * |component|
    sel = k == 0
    q[sel] = np.stack([0.25 * s[sel], (m[sel, 2, 1] - m[sel, 1, 2]) / s[sel],
                       (m[sel, 0, 2] - m[sel, 2, 0]) / s[sel], (m[sel, 1, 0] - m[sel, 0, 1]) / s[sel]], -1)
    sel = k == 1
    q[sel] = np.stack([(m[sel, 2, 1] - m[sel, 1, 2]) / s[sel], 0.25 * s[sel],
                       (m[sel, 0, 1] + m[sel, 1, 0]) / s[sel], (m[sel, 0, 2] + m[sel, 2, 0]) / s[sel]], -1)
    sel = k == 2
    q[sel] = np.stack([(m[sel, 0, 2] - m[sel, 2, 0]) / s[sel], (m[sel, 0, 1] + m[sel, 1, 0]) / s[sel],
                       0.25 * s[sel], (m[sel, 1, 2] + m[sel, 2, 1]) / s[sel]], -1)
    sel = k == 3
    q[sel] = np.stack([(m[sel, 1, 0] - m[sel, 0, 1]) / s[sel], (m[sel, 0, 2] + m[sel, 2, 0]) / s[sel],
                       (m[sel, 1, 2] + m[sel, 2, 1]) / s[sel], 0.25 * s[sel]], -1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def to_xyzw(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) ``[w, x, y, z]`` (this module's order) as ``[x, y, z, w]`` (the messages' and ROS's)."""
    return np.roll(np.asarray(q, dtype=np.float64), -1, axis=-1)


def to_wxyz(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) ``[x, y, z, w]`` as ``[w, x, y, z]``."""
    return np.roll(np.asarray(q, dtype=np.float64), 1, axis=-1)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (..., 4) wxyz, broadcasting."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], -1)


def rotvec_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) (axis times angle, rad) -> rotation matrices (..., 3, 3)."""
    v = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    # sin(angle / 2) / angle, by its series near 0 where the quotient loses precision
    small = angle < 1e-6
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(angle / 2) / np.where(small, 1.0, angle))
    return quaternion_to_matrix(np.concatenate([np.cos(angle / 2), v * scale], axis=-1))


def zxy_euler_deg(m: np.ndarray) -> np.ndarray:
    """Intrinsic Z-X-Y Euler angles (..., 3) in degrees of rotation matrices (..., 3, 3): ``m =
    Rz(a) Rx(b) Ry(c)`` (BVH's usual channel order), b in [-90, 90]. At b = +-90 (gimbal lock)
    c is 0 and a takes the whole turn about the vertical, so the angles still give ``m``."""
    m = np.asarray(m, dtype=np.float64)
    cos_b = np.hypot(m[..., 2, 0], m[..., 2, 2])
    b = np.arctan2(m[..., 2, 1], cos_b)
    locked = cos_b < 1e-9
    a = np.where(locked, np.arctan2(m[..., 1, 0], m[..., 0, 0]), np.arctan2(-m[..., 0, 1], m[..., 1, 1]))
    c = np.where(locked, 0.0, np.arctan2(-m[..., 2, 0], m[..., 2, 2]))
    return np.degrees(np.stack([a, b, c], axis=-1))
