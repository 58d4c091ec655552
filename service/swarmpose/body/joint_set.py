"""The full joint set: every joint the rig has, with a position and an orientation per pose.

Names follow Azure Kinect Body Tracking's joints where the rig has a counterpart
(:data:`SKELETON_JOINTS`, each with its ``K4ABT_JOINT_`` name); the 14 evaluation joints keep
their names and positions. Azure's HANDTIP and THUMB joints have no counterpart (the rigs have no
finger degrees of freedom).

Each joint is carried by one bone of the body's rig (:func:`rig_joints`), and its pose is that
bone's:

* **position**: a point rigidly attached to the bone, its rest position given by the body:
  the named point of the same name (the joint centres, the face points), except ``pelvis`` (the
  root bone's head: the pose's ``tx ty tz``), ``spine_navel`` (the ``spine`` point, the lower
  back's pivot), ``spine_chest`` (the head of the last bone the spine joint turns; with a
  one-bone spine, midway between the ``spine`` and ``neck`` points), ``left_hand`` /
  ``right_hand`` (the centroid of the rest vertices skinned mostly to the hand bone or a bone
  below it; the wrist where there are none) and ``left_foot`` / ``right_foot`` (the toe tip);
* **orientation**: the bone's *canonical frame* ``W_b`` of
  :func:`swarmpose.body.kinematics.canonical_rotations`, the rotation turning the body frame's
  axes as they are in the T-pose (X = the subject's left, Y = up, Z = forward) into the bone's
  axes now: ``W_b = Q_root E_1 ... E_b``, the root quaternion times the joint rotations from
  the root down to the bone (a bone sharing a joint with others takes its share ``E^f``).
  In the T-pose every joint's frame is the root's; a bone's direction to its child, expressed
  in its frame, is the same in every pose (:data:`BONE_AXES`).

Shapes: ``K`` = 28 joints, ``P`` poses; metres, the pose's frame (camera) for posed values.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from swarmpose.body.kinematics import transform_points
from swarmpose.body.skeleton import EVAL_JOINTS, JOINT_INDEX

if TYPE_CHECKING:  # the message builder imports this module; the command line's parser must not load scipy
    from swarmpose.body.skinned import SkinnedBody


@dataclass(frozen=True)
class SkeletonJoint:
    """One joint of the full set: our name, Azure Kinect BT's (``K4ABT_JOINT_<azure>``), the
    parent joint ("" for the root) and the evaluation joints whose mean confidence it takes."""

    name: str
    azure: str
    parent: str
    confidence_of: tuple[str, ...]


def _sided(name: str, azure: str, parent: str, confidence_of: str) -> tuple[SkeletonJoint, SkeletonJoint]:
    """The left and right joint (``parent`` and ``confidence_of`` sided unless unsided names)."""
    def side(s: str, word: str) -> str:
        return word if word in ("pelvis", "spine_chest", "head") else f"{s}_{word}"
    return tuple(SkeletonJoint(f"{s}_{name}", f"{azure}_{s.upper()}", side(s, parent), (side(s, confidence_of),))
                 for s in ("left", "right"))


SKELETON_JOINTS: tuple[SkeletonJoint, ...] = (
    SkeletonJoint("pelvis", "PELVIS", "", ("left_hip", "right_hip")),
    SkeletonJoint("spine_navel", "SPINE_NAVEL", "pelvis", ("left_hip", "right_hip", "left_shoulder", "right_shoulder")),
    SkeletonJoint("spine_chest", "SPINE_CHEST", "spine_navel", ("neck", "left_shoulder", "right_shoulder")),
    SkeletonJoint("neck", "NECK", "spine_chest", ("neck",)),
    SkeletonJoint("head", "HEAD", "neck", ("head",)),
    SkeletonJoint("nose", "NOSE", "head", ("head",)),
    *_sided("eye", "EYE", "head", "head"),
    *_sided("ear", "EAR", "head", "head"),
    *_sided("clavicle", "CLAVICLE", "spine_chest", "shoulder"),
    *_sided("shoulder", "SHOULDER", "clavicle", "shoulder"),
    *_sided("elbow", "ELBOW", "shoulder", "elbow"),
    *_sided("wrist", "WRIST", "elbow", "wrist"),
    *_sided("hand", "HAND", "wrist", "wrist"),
    *_sided("hip", "HIP", "pelvis", "hip"),
    *_sided("knee", "KNEE", "hip", "knee"),
    *_sided("ankle", "ANKLE", "knee", "ankle"),
    *_sided("foot", "FOOT", "ankle", "ankle"),
)
"""The 28 joints, parents first (Azure's order where it has the joint)."""

SKELETON_NAMES: tuple[str, ...] = tuple(j.name for j in SKELETON_JOINTS)
SKELETON_INDEX: dict[str, int] = {n: k for k, n in enumerate(SKELETON_NAMES)}
SKELETON_PARENTS: tuple[int, ...] = tuple(SKELETON_INDEX.get(j.parent, -1) for j in SKELETON_JOINTS)
"""Each joint's parent index (-1 for the pelvis); parents come before their children."""
SKELETON_LINKS: tuple[tuple[str, str], ...] = tuple((j.parent, j.name) for j in SKELETON_JOINTS if j.parent)
"""(parent, child) pairs: the bones to draw."""
EXTRA_JOINTS: tuple[str, ...] = tuple(n for n in SKELETON_NAMES if n not in EVAL_JOINTS)
"""The 14 joints the full set adds to the evaluation joints."""
AZURE_WITHOUT_COUNTERPART: tuple[str, ...] = ("HANDTIP_LEFT", "THUMB_LEFT", "HANDTIP_RIGHT", "THUMB_RIGHT")

_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
BONE_AXES: dict[str, tuple[float, float, float]] = {
    "pelvis": _Y, "spine_navel": _Y, "spine_chest": _Y, "neck": _Y, "head": _Z,
    "left_clavicle": _X, "left_shoulder": _X, "left_elbow": _X, "left_wrist": _X,
    "right_clavicle": (-1.0, 0.0, 0.0), "right_shoulder": (-1.0, 0.0, 0.0), "right_elbow": (-1.0, 0.0, 0.0),
    "right_wrist": (-1.0, 0.0, 0.0),
    "left_hip": (0.0, -1.0, 0.0), "left_knee": (0.0, -1.0, 0.0), "left_ankle": _Z,
    "right_hip": (0.0, -1.0, 0.0), "right_knee": (0.0, -1.0, 0.0), "right_ankle": _Z,
}
"""The T-pose axis (in the joint's own frame) its bone points along towards its first child. The
direction itself is the same in every pose; how near it is to this axis depends on the body (the
built-in and MakeHuman bodies): within 1 degree for the shoulders, hips and knees; within 12 for the
clavicles, elbows, wrists, spine and neck (what a joint's degrees of freedom cannot straighten
stays); 10-22 for the pelvis (the lower back lies behind the hips), the head (to the nose) and the
ankles (the toe lies below the ankle)."""


@dataclass(frozen=True)
class RigJoints:
    """Where the full set sits on one body's rig: per joint the bone (K,) int that carries it and
    its rest position (K, 3) m in the body frame."""

    bones: np.ndarray
    rest: np.ndarray


def _spine_chest(body: SkinnedBody) -> tuple[int, np.ndarray]:
    """The bone and rest position of ``spine_chest`` (see the module docstring)."""
    spine = body.bones_of_joint("spine")
    last = max(spine)  # topological order: the deepest of the chain
    if len(spine) > 1:
        return last, np.asarray(body.bone_heads[last], dtype=np.float64)
    return last, 0.5 * (body.point("spine") + body.point("neck"))


def _hand(body: SkinnedBody, side: str) -> tuple[int, np.ndarray]:
    """The bone and rest position of ``<side>_hand``: the centroid of the hand's vertices."""
    bone = int(body.point_bones[body.point_names.index(f"{side}_wrist")])
    below = {bone}
    for b in range(bone + 1, len(body.bone_parents)):  # topological: a bone's parent comes first
        if int(body.bone_parents[b]) in below:
            below.add(b)
    dominant = body.skin_indices[np.arange(len(body.vertices)), np.argmax(body.skin_weights, axis=1)]
    mine = np.isin(dominant, sorted(below))
    if not mine.any():
        return bone, body.point(f"{side}_wrist")
    return bone, np.asarray(body.vertices[mine], dtype=np.float64).mean(axis=0)


@functools.lru_cache(maxsize=32)
def rig_joints(body: SkinnedBody) -> RigJoints:
    """The bone and rest position of every joint of :data:`SKELETON_JOINTS` on ``body``."""
    special = {"pelvis": (0, np.asarray(body.bone_heads[0], dtype=np.float64)),
               "spine_navel": (None, body.point("spine")), "spine_chest": _spine_chest(body),
               "left_hand": _hand(body, "left"), "right_hand": _hand(body, "right"),
               "left_foot": (None, body.point("left_toe")), "right_foot": (None, body.point("right_toe"))}
    point_of = {"spine_navel": "spine", "left_foot": "left_toe", "right_foot": "right_toe"}
    bones, rest = [], []
    for name in SKELETON_NAMES:
        bone, position = special.get(name, (None, None))
        if position is None:
            position = body.point(name)
        if bone is None:
            bone = int(body.point_bones[body.point_names.index(point_of.get(name, name))])
        bones.append(int(bone))
        rest.append(position)
    return RigJoints(np.asarray(bones, dtype=np.int64), np.asarray(rest, dtype=np.float64))


def posed_joints(body: SkinnedBody, h: np.ndarray,
                 transforms: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The full set posed: positions (P, K, 3) m and orientations (P, K, 3, 3) (each joint's frame,
    columns its axes) in the poses' frame, for poses ``h`` (P, 36) or (36,) (then P = 1);
    ``transforms``: their bone transforms (P, B, 3, 4) where the caller has them (``body.transforms(h)``)."""
    on_rig = rig_joints(body)
    transforms = body.transforms(h) if transforms is None else transforms
    frames = transforms[:, on_rig.bones, :, :3] @ body.rig.rest_frames[on_rig.bones]  # D_b R_b = W_b
    return transform_points(on_rig.bones, on_rig.rest, transforms), frames


def skeleton_confidence(eval_confidence: np.ndarray) -> np.ndarray:
    """(K,) confidences of the full set from the 14 evaluation joints' (14,) (``EVAL_JOINTS``
    order): each joint the mean of its ``confidence_of`` joints'."""
    conf = np.asarray(eval_confidence, dtype=np.float64)
    index = {n: k for k, n in enumerate(EVAL_JOINTS)}
    return np.array([float(np.mean(conf[[index[n] for n in j.confidence_of]])) for j in SKELETON_JOINTS])


assert set(EVAL_JOINTS) <= set(SKELETON_NAMES) and len(SKELETON_NAMES) == 28
assert all(p < k for k, p in enumerate(SKELETON_PARENTS))
assert set(JOINT_INDEX) - {"spine", "left_collar", "right_collar"} <= set(SKELETON_NAMES)
