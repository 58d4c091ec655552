"""Batched forward kinematics and skinning in pure numpy: the oracle for the OpenCL kernels.

Conventions: quaternions are ``(w, x, y, z)``; rotation matrices act on column vectors;
``P`` poses, ``B`` bones, ``V`` vertices, ``K`` skin influences per vertex, ``J`` = 14
tracking joints. Positions are metres. Rest-pose geometry is in the body frame (see
:mod:`swarmpose.body.skeleton`); posed geometry is in the camera frame of the pose.

Joint angles are relative to the canonical T-pose (see :mod:`swarmpose.body.skeleton`);
a body whose rest pose differs (an A-pose) has *rest angles* and per-bone rest frames.
Skinning uses each bone's *delta from the rest pose* in rest (body-frame) coordinates, so
the bind rotations of a rig never enter: bone ``b`` maps a rest point ``v`` to
``D_b v + (x_b - D_b p_b)`` where ``p_b`` is its rest head, ``D_b`` its rotation from rest
and ``x_b`` its posed head.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from swarmpose.body.skeleton import (
    ANGLES,
    N_ANGLES,
    POSE_DIM,
    ROOT_QUATERNION,
    ROOT_TRANSLATION,
    TRACKING_JOINTS,
    angle_offset,
)
from swarmpose.core.errors import ShapeError, check_shape
from swarmpose.core.rotations import (  # noqa: F401  (re-exported: the body's modules import them from here)
    matrix_to_quaternion,
    quaternion_multiply,
    quaternion_to_matrix,
    to_wxyz,
    to_xyzw,
)


# ---------------------------------------------------------------------------- rotations
def axis_angle_matrix(axis, angle: np.ndarray) -> np.ndarray:
    """Rotation by ``angle`` (..., rad) about unit ``axis`` (3,) -> (..., 3, 3) (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle)[..., None, None], np.sin(angle)[..., None, None]
    kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) * c + s * kx + (1 - c) * np.outer(a, a)


def shortest_arc(src, dst) -> np.ndarray:
    """Rotations (..., 3, 3) of least angle turning directions ``src`` onto ``dst`` (..., 3).

    Opposite directions turn by pi about an axis perpendicular to ``src``.
    """
    a = np.asarray(src, dtype=np.float64)
    b = np.asarray(dst, dtype=np.float64)
    a, b = np.broadcast_arrays(a / np.linalg.norm(a, axis=-1, keepdims=True),
                               b / np.linalg.norm(b, axis=-1, keepdims=True))
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    opposite = c < -1 + 1e-9
    if np.any(opposite):  # any perpendicular axis will do
        helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        perp = np.cross(a, helper)
        perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
        v = np.where(opposite[..., None], perp, v)
    k = np.zeros(v.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    # Rodrigues with sin = |v|, cos = c; for the opposite case (|v| = 1 after replacement) 1 + cos -> 2 (pi turn).
    scale = np.where(opposite, 2.0, 1.0 / np.maximum(1.0 + c, 1e-12))
    return np.eye(3) + np.where(opposite[..., None, None], 0.0, k) + (k @ k) * scale[..., None, None]


def rotation_power(rot: np.ndarray, fraction: float | np.ndarray) -> np.ndarray:
    """``rot ** fraction`` (..., 3, 3): the same axis, ``fraction`` of the angle (< pi);
    ``fraction`` a number or an array broadcasting against ``rot.shape[:-2]``."""
    q = matrix_to_quaternion(rot)
    half = np.arccos(np.clip(q[..., 0], -1.0, 1.0))
    sin_half = np.sin(half)
    axis = np.where(sin_half[..., None] > 1e-12, q[..., 1:] / np.maximum(sin_half, 1e-12)[..., None], 0.0)
    return quaternion_to_matrix(np.concatenate([np.cos(fraction * half)[..., None],
                                                axis * np.sin(fraction * half)[..., None]], -1))


def compose_joint(joint, angles: np.ndarray) -> np.ndarray:
    """Canonical rotation ``E = R(compose[0]) R(compose[1]) ...`` (..., 3, 3) of one tracking
    joint (a :class:`~swarmpose.body.skeleton.TrackingJoint`) from its angles (..., n_dofs)
    in pose-vector DOF order, rad."""
    kinds = [d.kind for d in joint.dofs]
    rot = None
    for kind in joint.compose:
        k = kinds.index(kind)
        step = axis_angle_matrix(joint.dofs[k].axis, angles[..., k])
        rot = step if rot is None else rot @ step
    return rot


@functools.lru_cache(maxsize=1)
def _dof_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 29 DOFs' Rodrigues terms and each joint's composition order, built once.

    Returns ``skew`` (30, 3, 3) and ``outer`` (30, 3, 3) of the unit axes (row 29: an extra
    DOF whose angle is always 0, i.e. the identity) and ``steps`` (14, 3) int: the DOF rows
    of :func:`compose_joint`'s factors per joint, padded with 29."""
    axes = np.array([[0.0, 0.0, 1.0]] * (N_ANGLES + 1))
    steps = np.full((len(TRACKING_JOINTS), 3), N_ANGLES, np.int64)
    for ji, joint in enumerate(TRACKING_JOINTS):
        first = angle_offset(joint.name)
        kinds = [d.kind for d in joint.dofs]
        for k, dof in enumerate(joint.dofs):
            axes[first + k] = dof.axis
        steps[ji, :len(joint.compose)] = [first + kinds.index(kind) for kind in joint.compose]
    skew, outer = np.zeros((N_ANGLES + 1, 3, 3)), np.zeros((N_ANGLES + 1, 3, 3))
    for i, axis in enumerate(axes):
        a = axis / np.linalg.norm(axis)
        skew[i] = [[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]]
        outer[i] = np.outer(a, a)
    return skew, outer, steps


def joint_rotations(angles: np.ndarray, fraction: float = 1.0) -> np.ndarray:
    """Canonical-frame joint rotations ``E_j`` (P, 14, 3, 3) from angles (P, 29) rad.

    ``E_j`` is :func:`compose_joint` of the joint's DOFs (see skeleton), computed for all
    joints at once (the same products in the same order, bit for bit). With ``fraction``
    f < 1 it returns ``E_j ** f`` (same axis, f of the angle), so that k bones sharing a
    joint with f = 1/k compose to exactly ``E_j``.
    """
    angles = np.asarray(angles, dtype=np.float64)
    skew, outer, steps = _dof_tables()
    padded = np.concatenate([angles, np.zeros(angles.shape[:-1] + (1,))], axis=-1)
    c, s = np.cos(padded)[..., None, None], np.sin(padded)[..., None, None]
    dof = np.eye(3) * c + s * skew + (1 - c) * outer  # (P, 30, 3, 3), row 29 the identity
    out = (dof[..., steps[:, 0], :, :] @ dof[..., steps[:, 1], :, :]) @ dof[..., steps[:, 2], :, :]
    return out if fraction == 1.0 else rotation_power(out, fraction)


# ---------------------------------------------------------------------------- rig and FK
@dataclass(frozen=True)
class Rig:
    """The arrays forward kinematics needs, in topological order (``parents[b] < b``).

    parents: (B,) int, -1 for the root bone (index 0).
    heads: (B, 3) float, rest head (pivot) of each bone in the body frame, metres.
    bone_joint: (B,) int, tracking joint that rotates the bone, -1 if rigid to its parent.
    bone_fraction: (B,) float, share of that joint's angles the bone takes.
    rest_frames: (B, 3, 3) float, each bone's canonical frame in the rest pose, i.e.
        :func:`canonical_rotations` at the body's rest angles with an identity root.
    """

    parents: np.ndarray
    heads: np.ndarray
    bone_joint: np.ndarray
    bone_fraction: np.ndarray
    rest_frames: np.ndarray

    def __post_init__(self) -> None:
        b = len(self.parents)
        check_shape("rig.heads", self.heads, (b, 3))
        check_shape("rig.bone_joint", self.bone_joint, (b,))
        check_shape("rig.bone_fraction", self.bone_fraction, (b,))
        check_shape("rig.rest_frames", self.rest_frames, (b, 3, 3))
        if self.parents[0] != -1 or np.any(self.parents[1:] >= np.arange(1, b)) or np.any(self.parents[1:] < 0):
            raise ShapeError("rig.parents must list bones in topological order with the root first")


def as_poses(h: np.ndarray) -> np.ndarray:
    """Poses (P, 36) as float64, or a ShapeError for a wrong shape, non-finite values or a
    zero root quaternion (naming the offending rows)."""
    h = np.asarray(h, dtype=np.float64)
    if h.ndim != 2 or h.shape[1] != POSE_DIM:
        raise ShapeError(f"poses have shape {h.shape}, expected (P, {POSE_DIM})")
    bad = ~np.all(np.isfinite(h), axis=1) | (np.linalg.norm(h[:, ROOT_QUATERNION], axis=1) < 1e-9)
    if np.any(bad):
        rows = np.flatnonzero(bad)
        raise ShapeError(f"poses {rows[:10].tolist()} have non-finite values or a zero root quaternion; "
                         "every pose needs finite numbers and a non-zero quaternion")
    return h


@functools.lru_cache(maxsize=16)
def _bone_levels(parents: bytes) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The bones (after the root) grouped by depth in the tree: per level (bones, their
    parents), int arrays; ``parents`` is the (B,) int64 parent array's bytes."""
    par = np.frombuffer(parents, dtype=np.int64)
    depth = np.zeros(len(par), np.int64)
    for bone in range(1, len(par)):
        depth[bone] = depth[par[bone]] + 1
    return tuple((np.flatnonzero(depth == d), par[depth == d]) for d in range(1, int(depth.max(initial=0)) + 1))


@functools.lru_cache(maxsize=16)
def _bone_shares(joints: bytes, fractions: bytes) -> tuple[np.ndarray, ...]:
    """Which bones (after the root) take a whole joint rotation and which a power of one, from
    the (B,) int64 ``bone_joint`` and float64 ``bone_fraction`` arrays' bytes.

    Returns ``whole`` (bones) and ``whole_joint`` (their joints); ``part`` (bones); the distinct
    (joint, fraction) pairs among ``part`` as ``pair_joint`` (int) and ``pair_fraction``; and
    ``pair_of_part``: for each bone of ``part`` the index of its pair (each power is taken once)."""
    joint = np.frombuffer(joints, dtype=np.int64)
    fraction = np.frombuffer(fractions, dtype=np.float64)
    moved = (joint >= 0) & (np.arange(len(joint)) > 0)
    whole = np.flatnonzero(moved & (fraction == 1.0))
    part = np.flatnonzero(moved & (fraction != 1.0))
    pairs, pair_of_part = np.unique(np.stack([joint[part], fraction[part]], -1).reshape(-1, 2), axis=0,
                                    return_inverse=True)
    return whole, joint[whole], part, pairs[:, 0].astype(np.int64), pairs[:, 1], pair_of_part.reshape(-1)


def canonical_rotations(parents: np.ndarray, bone_joint: np.ndarray, bone_fraction: np.ndarray,
                        root: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Canonical bone frames (P, B, 3, 3): ``W_b = W_parent E_j(f_b a_j)``, ``W_root = root``.

    root: (P, 3, 3) root rotations; angles: (P, 29) rad. At zero angles every frame
    equals the root's: zero angles are the T-pose of :mod:`swarmpose.body.skeleton`.
    The bones of one depth in the tree are multiplied together.
    """
    p, b = angles.shape[0], len(parents)
    whole, whole_joint, part, pair_joint, pair_fraction, pair_of_part = _bone_shares(
        np.asarray(bone_joint, dtype=np.int64).tobytes(), np.asarray(bone_fraction, dtype=np.float64).tobytes())
    full = joint_rotations(angles)  # every joint once; bones sharing a joint take a power of it
    local = np.empty((p, b, 3, 3))
    local[:] = np.eye(3)  # rigid bones: the parent's frame
    local[:, whole] = full[:, whole_joint]
    if len(part):  # each (joint, fraction) once: bones sharing it take the same power
        powers = rotation_power(full[:, pair_joint], pair_fraction)
        local[:, part] = powers[:, pair_of_part]
    rot = np.empty((p, b, 3, 3))
    rot[:, 0] = root
    for bones, above in _bone_levels(np.asarray(parents, dtype=np.int64).tobytes()):
        rot[:, bones] = rot[:, above] @ local[:, bones]
    return rot


def forward_kinematics(rig: Rig, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posed bone rotations (P, B, 3, 3) and heads (P, B, 3) in the camera frame for poses (P, 36).

    The rotation of bone ``b`` is the delta from the rest pose ``D_b = W_b(h) R_b^T``
    (``R_b`` = the rig's rest frame), so the rest pose reproduces the rest mesh exactly.
    The root bone's head goes to ``h[0:3]``; the quaternion ``h[3:7]`` turns the body
    frame into the camera frame.
    """
    h = as_poses(h)
    root = quaternion_to_matrix(h[:, ROOT_QUATERNION])
    frames = canonical_rotations(rig.parents, rig.bone_joint, rig.bone_fraction, root, h[:, ANGLES])
    rot = frames @ np.swapaxes(rig.rest_frames, -1, -2)
    p, b = h.shape[0], len(rig.parents)
    pos = np.empty((p, b, 3))
    pos[:, 0] = h[:, ROOT_TRANSLATION]
    heads = np.asarray(rig.heads, dtype=np.float64)
    for bones, above, offset in _level_offsets(np.asarray(rig.parents, dtype=np.int64).tobytes(), heads.tobytes()):
        pos[:, bones] = pos[:, above] + (rot[:, above] @ offset)[..., 0]
    return rot, pos


@functools.lru_cache(maxsize=16)
def _level_offsets(parents: bytes, heads: bytes) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
    """:func:`_bone_levels` with each level's rest offsets from the parents' heads (n, 3, 1) m, from the
    (B,) int64 parents' and the (B, 3) float64 heads' bytes (a rig's, built once)."""
    rest = np.frombuffer(heads, dtype=np.float64).reshape(-1, 3)
    levels = tuple((bones, above, (rest[bones] - rest[above])[..., None]) for bones, above in _bone_levels(parents))
    for _, _, offset in levels:
        offset.setflags(write=False)  # cached: shared by every call
    return levels


def skinning_transforms(rig: Rig, h: np.ndarray) -> np.ndarray:
    """Affine bone transforms (P, B, 3, 4) mapping rest body-frame points to the camera frame."""
    rot, pos = forward_kinematics(rig, h)
    trans = pos - np.einsum("pbij,bj->pbi", rot, rig.heads)
    return np.concatenate([rot, trans[..., None]], axis=-1)


# ---------------------------------------------------------------------------- skinning
def _check_skin(vertices, indices, weights, transforms) -> None:
    check_shape("vertices", vertices, (None, 3))
    v = len(vertices)
    check_shape("skin indices", indices, (v, None))
    check_shape("skin weights", weights, (v, indices.shape[1]))
    check_shape("transforms", transforms, (None, None, 3, 4))


def linear_blend_skinning(vertices: np.ndarray, indices: np.ndarray, weights: np.ndarray,
                          transforms: np.ndarray) -> np.ndarray:
    """LBS: rest vertices (V, 3), influences (V, K) int + (V, K) weights, transforms (P, B, 3, 4)
    -> posed vertices (P, V, 3): ``sum_k w_k (R_k v + t_k)``."""
    _check_skin(vertices, indices, weights, transforms)
    blended = np.einsum("vk,pvkij->pvij", weights, transforms[:, indices])  # (P, V, 3, 4)
    return np.einsum("pvij,vj->pvi", blended[..., :3], vertices) + blended[..., 3]


def transforms_to_dual_quaternions(transforms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transforms (..., 3, 4) -> (real, dual) unit dual quaternions, each (..., 4)."""
    real = matrix_to_quaternion(transforms[..., :3])
    t = np.concatenate([np.zeros(transforms.shape[:-2] + (1,)), transforms[..., 3]], -1)
    return real, 0.5 * quaternion_multiply(t, real)


def dual_quaternion_skinning(vertices: np.ndarray, indices: np.ndarray, weights: np.ndarray,
                             transforms: np.ndarray) -> np.ndarray:
    """DQS (Kavan et al. 2007): same inputs and output as :func:`linear_blend_skinning`.

    Each influence's quaternion is flipped into the hemisphere of the vertex's first
    influence before blending, so a vertex never blends the long way round.
    """
    _check_skin(vertices, indices, weights, transforms)
    real, dual = transforms_to_dual_quaternions(transforms)  # (P, B, 4)
    r, d = real[:, indices], dual[:, indices]  # (P, V, K, 4)
    sign = np.sign(np.sum(r * r[:, :, :1], axis=-1, keepdims=True))
    sign[sign == 0] = 1
    w = weights[None, :, :, None] * sign
    br, bd = np.sum(w * r, axis=2), np.sum(w * d, axis=2)  # (P, V, 4)
    norm = np.linalg.norm(br, axis=-1, keepdims=True)
    br, bd = br / norm, bd / norm
    rot = quaternion_to_matrix(br)
    conj = br * np.array([1, -1, -1, -1])
    trans = 2 * quaternion_multiply(bd, conj)[..., 1:]
    return np.einsum("pvij,vj->pvi", rot, vertices) + trans


def transform_points(bones: np.ndarray, rest: np.ndarray, transforms: np.ndarray) -> np.ndarray:
    """Points rigidly attached to bones: bone index (N,), rest positions (N, 3) -> (P, N, 3)."""
    check_shape("rest points", rest, (len(bones), 3))
    t = transforms[:, bones]  # (P, N, 3, 4)
    return np.einsum("pnij,nj->pni", t[..., :3], rest) + t[..., 3]


def root_turn_deg(a: np.ndarray, b: np.ndarray) -> float | np.ndarray:
    """The angle (degrees) of the rotation between the root orientations of pose a (36,) and
    pose b (36,), or of each of poses b (P, 36) (unit or not: the quaternions are normalised)."""
    qa, qb = a[3:7] / np.linalg.norm(a[3:7]), b[..., 3:7] / np.linalg.norm(b[..., 3:7], axis=-1, keepdims=True)
    turn = np.degrees(2.0 * np.arccos(np.clip(np.abs(qb @ qa), 0.0, 1.0)))
    return float(turn) if turn.ndim == 0 else turn
