"""What the ROS 2 bag says about one body: its joints as a chain of parent-relative transforms
(for ``tf2_msgs/msg/TFMessage``) and as the points of its skeleton drawing (for markers).

Pure numpy on the frame message's values, so the bag holds what ``poses.jsonl`` holds.
Shapes: ``K`` = 28 joints of :data:`~swarmpose.body.joint_set.SKELETON_JOINTS`, parents
first; metres; quaternions ``[x, y, z, w]`` (ROS order, as the messages' ``orientation_xyzw``).

A joint ``k`` with parent ``p`` (position ``x``, rotation ``R`` of the unit quaternion ``q``, both
in the message's coordinates) is sent relative to its parent: translation ``R_p^T (x_k - x_p)``
and rotation ``q_p^-1 q_k``; the pelvis, the root, relative to the message's frame (the camera or
the world): ``x_pelvis`` and ``q_pelvis``. Composing the chain from the root down gives back every
joint's position and orientation.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.joint_set import SKELETON_INDEX, SKELETON_LINKS, SKELETON_NAMES, SKELETON_PARENTS
from swarmpose.body.kinematics import quaternion_multiply, quaternion_to_matrix, to_wxyz, to_xyzw


def body_joints(body: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """A frame message body's joint positions (K, 3) m and unit orientations (K, 4) ``[x, y, z,
    w]`` (normalised: the message rounds them to 6 digits), in :data:`SKELETON_NAMES` order; None
    when any joint lacks either (a body without a pose)."""
    joints = body.get("joints") or {}
    positions, orientations = [], []
    for name in SKELETON_NAMES:
        joint = joints.get(name) or {}
        p, q = joint.get("position_m"), joint.get("orientation_xyzw")
        if p is None or q is None or None in p or None in q:
            return None
        positions.append(p)
        orientations.append(q)
    q = np.asarray(orientations, dtype=np.float64)
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    if not np.all(norm > 0.5):  # not a rotation: nothing sensible to send
        return None
    return np.asarray(positions, dtype=np.float64), q / norm


def parent_relative(positions: np.ndarray, orientations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each joint relative to its parent (the pelvis to the frame the values are in): translations
    (K, 3) m in the parent's axes and rotations (K, 4) ``[x, y, z, w]`` (w >= 0), from positions
    (K, 3) m and unit orientations (K, 4) in :data:`SKELETON_NAMES` order."""
    parents = np.asarray(SKELETON_PARENTS)
    has_parent = parents >= 0
    parent_q = np.where(has_parent[:, None], orientations[np.maximum(parents, 0)], [0.0, 0.0, 0.0, 1.0])
    parent_x = np.where(has_parent[:, None], positions[np.maximum(parents, 0)], 0.0)
    rotation_t = np.swapaxes(quaternion_to_matrix(to_wxyz(parent_q)), -1, -2)
    translations = np.einsum("kij,kj->ki", rotation_t, positions - parent_x)
    inverse = parent_q * np.array([-1.0, -1.0, -1.0, 1.0])
    rotations = to_xyzw(quaternion_multiply(to_wxyz(inverse), to_wxyz(orientations)))
    rotations *= np.where(rotations[:, 3:] < 0, -1.0, 1.0)
    return translations, rotations


def link_points(positions: np.ndarray) -> np.ndarray:
    """The skeleton's lines as point pairs (2 L, 3) m, parent then child per link of
    :data:`SKELETON_LINKS` (a ``LINE_LIST``), from joint positions (K, 3)."""
    pairs = [k for parent, child in SKELETON_LINKS for k in (SKELETON_INDEX[parent], SKELETON_INDEX[child])]
    return np.asarray(positions, dtype=np.float64)[pairs]


__all__ = ["body_joints", "link_points", "parent_relative"]
