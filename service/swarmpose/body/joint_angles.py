"""Joint angles from rotations: decomposition into a joint's DOFs, and a body's rest angles.

Zero angles are the canonical T-pose (:mod:`swarmpose.body.skeleton`). A body standing
in another rest pose (MakeHuman's and the built-in body's A-pose, elbows slightly bent)
has *rest angles*: the angles that point each of its segments along its rest direction.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from swarmpose.body.kinematics import compose_joint, shortest_arc
from swarmpose.body.skeleton import ANGLE_LIMITS, N_ANGLES, TRACKING_JOINTS, angle_offset

_AXIS_LETTER = {0: "X", 1: "Y", 2: "Z"}


def joint_depth(name: str) -> int:
    """Number of tracking joints between ``name`` and the root (the spine has depth 1)."""
    parents = {j.name: j.parent for j in TRACKING_JOINTS}
    depth = 0
    while name != "root":
        name, depth = parents[name], depth + 1
    return depth


TOPOLOGICAL_ORDER: tuple[int, ...] = tuple(
    sorted(range(len(TRACKING_JOINTS)), key=lambda j: joint_depth(TRACKING_JOINTS[j].name)))
"""Tracking joint indices, every parent before its children."""


def joint_rotation(joint_index: int, angles: np.ndarray) -> np.ndarray:
    """Canonical rotation ``E_j`` (N, 3, 3) of one joint from its angles (N, n_dofs)."""
    return compose_joint(TRACKING_JOINTS[joint_index], np.asarray(angles, dtype=np.float64))


def decompose_joint(joint_index: int, rotation: np.ndarray) -> np.ndarray:
    """Angles (N, n_dofs) of tracking joint ``joint_index`` best matching rotations (N, 3, 3)
    in its canonical frame; pose-vector DOF order, not clamped.

    Three DOFs: Euler angles in ``compose`` order. Two DOFs: the same with the missing
    twist appended last and dropped, so the segment direction is kept exactly. One DOF:
    the angle about its axis that best aligns the segment's rest direction.
    """
    joint = TRACKING_JOINTS[joint_index]
    kinds = [d.kind for d in joint.dofs]
    out = np.zeros((len(rotation), len(kinds)))
    if len(joint.compose) == 1:
        a = np.asarray(joint.dofs[0].axis)
        c = np.asarray(joint.rest_direction)
        v = rotation @ c
        out[:, 0] = np.arctan2(np.cross(c, v) @ a, v @ c - (a @ c) * (v @ a))
        return out
    axes = [np.asarray(joint.dof(k).axis) for k in joint.compose]
    letters = [_AXIS_LETTER[int(np.argmax(np.abs(ax)))] for ax in axes]
    signs = [float(np.sign(ax[np.argmax(np.abs(ax))])) for ax in axes]
    if len(letters) == 2:
        letters.append(next(t for t in "XYZ" if t not in letters))
    from scipy.spatial.transform import Rotation  # here: scipy.spatial takes 0.5 s to import; retargeting needs it

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: scipy picks one of the solutions
        euler = Rotation.from_matrix(rotation).as_euler("".join(letters))
    for i, kind in enumerate(joint.compose):
        out[:, kinds.index(kind)] = signs[i] * euler[:, i]
    return out


def clamp_joint(joint_index: int, angles: np.ndarray) -> np.ndarray:
    """Angles (N, n_dofs) of one joint clipped to Table 1."""
    lo = angle_offset(TRACKING_JOINTS[joint_index].name)
    hi = lo + len(TRACKING_JOINTS[joint_index].dofs)
    return np.clip(angles, ANGLE_LIMITS[lo:hi, 0], ANGLE_LIMITS[lo:hi, 1])


def rest_angles(point: Callable[[str], np.ndarray]) -> np.ndarray:
    """The (29,) angles that point every segment of a body along its rest direction.

    ``point(name)`` gives a named point's rest position (3,) in the body frame. Each
    segment is swung (no twist) from its T-pose direction onto its reference direction
    (pivot -> child; heel -> toe for the feet) seen from its parent's frame, then
    clamped to Table 1.
    """
    angles = np.zeros(N_ANGLES)
    frames: dict[str, np.ndarray] = {"root": np.eye(3)}
    for j in TOPOLOGICAL_ORDER:
        joint = TRACKING_JOINTS[j]
        parent = frames[joint.parent]
        local_dir = parent.T @ (point(joint.reference[1]) - point(joint.reference[0]))
        swing = shortest_arc(joint.rest_direction, local_dir)
        ang = clamp_joint(j, decompose_joint(j, swing[None]))
        start = angle_offset(joint.name)
        angles[start:start + len(joint.dofs)] = ang[0]
        frames[joint.name] = parent @ joint_rotation(j, ang)[0]
    return angles
