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
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = 1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = 2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)
    m[..., 2, 0], m[..., 2, 1], m[..., 2, 2] = 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)
    return m


_BRANCH_TERMS = np.array([[0, 1, 2, 3], [1, 0, 4, 5], [2, 4, 0, 6], [3, 5, 6, 0]])
"""For each of :func:`matrix_to_quaternion`'s four formulas, which of its seven terms make w, x, y, z."""
_DIAGONAL = np.array([0, 4, 8])
_TERM_FIRST, _TERM_SECOND = np.array([7, 2, 3, 1, 2, 5]), np.array([5, 6, 1, 3, 6, 7])
"""The flat (row-major) entries of the six other terms: m21 - m12, m02 - m20, m10 - m01, m01 + m10, m02 + m20,
m12 + m21, each ``first - second`` (the three differences) or ``first + second`` (the three sums)."""


def matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) wxyz with w >= 0.

    Of the four textbook formulas, each matrix takes the one with the largest denominator
    (the numerically stable one); all are computed for every matrix and the right one picked,
    which for the few matrices a frame converts is several times faster than masking."""
    m = np.asarray(m, dtype=np.float64)
    flat = m.reshape(m.shape[:-2] + (9,))
    tr = np.trace(m, axis1=-2, axis2=-1)[..., None]
    cand = np.concatenate([tr, 2 * flat[..., _DIAGONAL] - tr], -1)
    s = np.sqrt(np.maximum(1.0 + np.max(cand, axis=-1, keepdims=True), 1e-300)) * 2  # 4 * |largest component|
    first, second = flat[..., _TERM_FIRST], flat[..., _TERM_SECOND]
    terms = np.concatenate([0.25 * s, (first[..., :3] - second[..., :3]) / s,
                            (first[..., 3:] + second[..., 3:]) / s], -1)
    q = np.take_along_axis(terms, _BRANCH_TERMS[np.argmax(cand, axis=-1)], -1)
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
