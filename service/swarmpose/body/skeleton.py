"""The 29-DOF tracking skeleton, the 36-D pose vector and the keypoint layouts.

Body frame
----------
Every body model is expressed in one *body frame*: X = the subject's left, Y = up,
Z = forward (out of the chest), metres, right-handed. glTF uses the same axes for a
character facing +Z, and the MakeHuman base mesh does too (after decimetres -> metres).

Pose vector
-----------
``h = [tx, ty, tz, qw, qx, qy, qz, a_0 .. a_28]`` (36 values): the root joint (pelvis)
position in the camera frame (OpenCV: x right, y down, z forward; metres), the unit
quaternion rotating body-frame vectors into the camera frame, then the 29 joint angles
(radians) of the paper's Table 1 in its order (Neck, Spine, LC, RC, LS, RS, LE, RE, LH,
RH, LK, RK, LA, RA; roll, pitch, yaw as present). A body upright facing the camera has
``q = (0, 1, 0, 0)`` (180 degrees about x).

Joint axes (the same for every body model)
------------------------------------------
Each joint rotates about body-frame axes *as they are in a T-pose*: roll about Z
(forward), yaw about Y (up), pitch about X (left), except hips and knees whose pitch
axis is -X so that the Table 1 ranges mean the anatomical motion:

* spine, neck: pitch > 0 bends forward, roll bends sideways, spine yaw twists;
* hip: pitch > 0 swings the thigh forward (flexion, up to 2 rad), roll abducts,
  yaw rotates the leg about its length; knee: pitch < 0 flexes (to -2.8 rad);
* shoulder: roll raises the arm in the frontal plane, yaw swings it forward/back
  (left: yaw < 0 is forward, right: yaw > 0), pitch twists it about its length;
* elbow: yaw flexes (left negative, right positive, as Table 1 mirrors them);
* collar: roll elevates, yaw protracts/retracts; ankle: pitch > 0 points the toes down
  (plantar flexion), yaw turns the foot.

All angles zero is the T-pose (arms straight out sideways, legs straight down, feet
flat and forward) on every body, so an angle means the same on every body. A body whose rest pose
is not a T-pose (MakeHuman and the built-in body stand in an A-pose, MakeHuman's
elbows bent)
has *rest angles* (:func:`swarmpose.body.joint_angles.rest_angles`), and skinning uses
each bone's rotation relative to its rest frame, so the rest angles give the rest mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

X = (1.0, 0.0, 0.0)
Y = (0.0, 1.0, 0.0)
Z = (0.0, 0.0, 1.0)
NEG_X = (-1.0, 0.0, 0.0)

POSE_DIM = 36
N_ANGLES = 29
ROOT_TRANSLATION = slice(0, 3)
ROOT_QUATERNION = slice(3, 7)
ANGLES = slice(7, 36)


@dataclass(frozen=True)
class Dof:
    """One rotational degree of freedom: its Table 1 name, body-frame axis and limits (rad)."""

    kind: str
    axis: tuple[float, float, float]
    lo: float
    hi: float


@dataclass(frozen=True)
class TrackingJoint:
    """A joint of the tracking skeleton.

    ``dofs`` are in pose-vector order (roll, pitch, yaw as present); ``compose`` lists
    the same DOF kinds in multiplication order, ``E = R(compose[0]) @ R(compose[1]) ...``,
    with the twist about the segment's own length last so that dropping it leaves the
    segment direction unchanged. ``pivot`` and ``child`` are named points; the segment's
    direction is measured between the ``reference`` points (pivot -> child, except the
    feet: heel -> toe, horizontal when the sole is flat), and is ``rest_direction`` in
    the T-pose.
    """

    name: str
    parent: str
    pivot: str
    child: str
    rest_direction: tuple[float, float, float]
    dofs: tuple[Dof, ...]
    compose: tuple[str, ...]
    reference: tuple[str, str] = ("", "")

    def __post_init__(self) -> None:
        if self.reference == ("", ""):
            object.__setattr__(self, "reference", (self.pivot, self.child))

    def dof(self, kind: str) -> Dof:
        """The DOF named ``kind`` ('roll', 'pitch' or 'yaw')."""
        for d in self.dofs:
            if d.kind == kind:
                return d
        raise KeyError(f"{self.name} has no {kind}")


def _limb_pair(name: str, parent: str, pivot: str, child: str, direction_left, direction_right,
               left_dofs: tuple[Dof, ...], right_dofs: tuple[Dof, ...], compose: tuple[str, ...],
               reference: tuple[str, str] | None = None):
    """The left and right joint of a limb; ``parent`` is sided unless it is spine or root."""
    sided_parent = parent not in ("spine", "root")
    return tuple(
        TrackingJoint(f"{side}_{name}", f"{side}_{parent}" if sided_parent else parent,
                      f"{side}_{pivot}", f"{side}_{child}", direction, dofs, compose,
                      (f"{side}_{reference[0]}", f"{side}_{reference[1]}") if reference else ("", ""))
        for side, direction, dofs in (("left", direction_left, left_dofs), ("right", direction_right, right_dofs))
    )


_DOWN = (0.0, -1.0, 0.0)
_LEFT = (1.0, 0.0, 0.0)
_RIGHT = (-1.0, 0.0, 0.0)

TRACKING_JOINTS: tuple[TrackingJoint, ...] = (
    TrackingJoint("neck", "spine", "neck", "head", Y,
                  (Dof("roll", Z, -0.4, 0.4), Dof("pitch", X, -0.3, 0.3)), ("roll", "pitch")),
    TrackingJoint("spine", "root", "spine", "neck", Y,
                  (Dof("roll", Z, -0.5, 0.5), Dof("pitch", X, -0.2, 0.5), Dof("yaw", Y, -1.5, 1.5)),
                  ("roll", "pitch", "yaw")),
    *_limb_pair("collar", "spine", "clavicle", "shoulder", _LEFT, _RIGHT,
                (Dof("roll", Z, -0.1, 0.1), Dof("yaw", Y, -0.15, 0.1)),
                (Dof("roll", Z, -0.1, 0.1), Dof("yaw", Y, -0.1, 0.15)), ("roll", "yaw")),
    *_limb_pair("shoulder", "collar", "shoulder", "elbow", _LEFT, _RIGHT,
                (Dof("roll", Z, -4.0, 4.0), Dof("pitch", X, -1.8, 1.57), Dof("yaw", Y, -2.0, 1.4)),
                (Dof("roll", Z, -4.0, 4.0), Dof("pitch", X, -1.8, 1.57), Dof("yaw", Y, -1.4, 2.0)),
                ("roll", "yaw", "pitch")),
    *_limb_pair("elbow", "shoulder", "elbow", "wrist", _LEFT, _RIGHT,
                (Dof("yaw", Y, -2.5, 0.0),), (Dof("yaw", Y, 0.0, 2.5),), ("yaw",)),
    *_limb_pair("hip", "root", "hip", "knee", _DOWN, _DOWN,
                (Dof("roll", Z, -1.57, 1.57), Dof("pitch", NEG_X, -0.78, 2.0), Dof("yaw", Y, -1.2, 0.5)),
                (Dof("roll", Z, -1.57, 1.57), Dof("pitch", NEG_X, -0.78, 2.0), Dof("yaw", Y, -0.5, 1.2)),
                ("roll", "pitch", "yaw")),
    *_limb_pair("knee", "hip", "knee", "ankle", _DOWN, _DOWN,
                (Dof("pitch", NEG_X, -2.8, 0.1),), (Dof("pitch", NEG_X, -2.8, 0.1),), ("pitch",)),
    *_limb_pair("ankle", "knee", "ankle", "toe", Z, Z,
                (Dof("pitch", X, -0.6, 0.6), Dof("yaw", Y, -0.7, 0.7)),
                (Dof("pitch", X, -0.6, 0.6), Dof("yaw", Y, -0.7, 0.7)), ("yaw", "pitch"), ("heel", "toe")),
)

JOINT_NAMES: tuple[str, ...] = tuple(j.name for j in TRACKING_JOINTS)
JOINT_INDEX: dict[str, int] = {n: i for i, n in enumerate(JOINT_NAMES)}


def _angle_table() -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    names, limits, owner = [], [], []
    for ji, joint in enumerate(TRACKING_JOINTS):
        for dof in joint.dofs:
            names.append(f"{joint.name}.{dof.kind}")
            limits.append((dof.lo, dof.hi))
            owner.append(ji)
    return tuple(names), np.asarray(limits, dtype=np.float64), np.asarray(owner, dtype=np.int64)


ANGLE_NAMES, ANGLE_LIMITS, ANGLE_JOINT = _angle_table()
"""``ANGLE_NAMES[k]`` names angle ``h[7 + k]``; ``ANGLE_LIMITS`` is (29, 2) [lo, hi] in rad."""

assert len(ANGLE_NAMES) == N_ANGLES


def angle_offset(joint: str) -> int:
    """Index into the 29 angles of the first DOF of tracking joint ``joint``."""
    ji = JOINT_INDEX[joint]
    return int(np.flatnonzero(ANGLE_JOINT == ji)[0])


# Named points every body model provides (rest position + the bone that carries them).
EVAL_JOINTS: tuple[str, ...] = (
    "head", "neck", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee",
    "left_ankle", "right_ankle",
)
"""The joints Δ and A(t) are measured on (paper §3.2)."""

EVAL_LINKS: tuple[tuple[str, str], ...] = (
    ("head", "neck"), ("neck", "left_shoulder"), ("neck", "right_shoulder"),
    ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"),
    ("right_shoulder", "right_elbow"), ("right_elbow", "right_wrist"),
    ("left_shoulder", "left_hip"), ("right_shoulder", "right_hip"), ("left_hip", "right_hip"),
    ("left_hip", "left_knee"), ("left_knee", "left_ankle"), ("right_hip", "right_knee"), ("right_knee", "right_ankle"),
)
"""Pairs of evaluation joints drawn as bones (overlays, viewers)."""

POINT_NAMES: tuple[str, ...] = EVAL_JOINTS + (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "mid_hip",
    "left_heel", "right_heel", "left_toe", "right_toe", "spine", "left_clavicle", "right_clavicle",
)
"""Every named point: evaluation joints, face and foot landmarks, internal pivots.

``head`` is the centre of the head (midway between the skull base and the crown), ``neck``
the base of the neck, ``shoulder``/``elbow``/``wrist``/``hip``/``knee``/``ankle`` the joint
centres, ``mid_hip`` the midpoint of the hips, ``toe`` the tip of the foot (big toe),
``spine`` the pivot of the spine joint (lower back), ``clavicle`` the sternoclavicular pivot.
"""

JOINT_WEIGHTS: dict[str, float] = {
    "left_hip": 0.2, "right_hip": 0.2, "mid_hip": 0.2,
    "left_wrist": 1.8, "right_wrist": 1.8, "left_ankle": 1.8, "right_ankle": 1.8,
}
"""Paper §2.3.2: w = 0.2 for hips, 1.8 for wrists and ankles, 1 otherwise."""


def joint_weight(point: str) -> float:
    """The objective weight of named point ``point``."""
    return JOINT_WEIGHTS.get(point, 1.0)


@dataclass(frozen=True)
class KeypointLayout:
    """A 2D detector's keypoint list and each keypoint's named body point (or None)."""

    name: str
    keypoints: tuple[str, ...]
    points: tuple[str | None, ...]

    def __post_init__(self) -> None:
        assert len(self.keypoints) == len(self.points)

    def point_of(self, keypoint: str) -> str | None:
        """The body point a keypoint corresponds to, None if the body has none."""
        return self.points[self.keypoints.index(keypoint)]

    @property
    def mapped(self) -> dict[str, str]:
        """Keypoint name -> body point, for the keypoints the body models."""
        return {k: p for k, p in zip(self.keypoints, self.points) if p is not None}


_COCO = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
         "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
         "left_knee", "right_knee", "left_ankle", "right_ankle")
COCO17 = KeypointLayout("coco17", _COCO, _COCO)

_BODY25 = ("nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow",
           "left_wrist", "mid_hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee",
           "left_ankle", "right_eye", "left_eye", "right_ear", "left_ear", "left_big_toe",
           "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel")
BODY25 = KeypointLayout(
    "body25", _BODY25,
    tuple({"left_big_toe": "left_toe", "right_big_toe": "right_toe",
           "left_small_toe": None, "right_small_toe": None}.get(k, k) for k in _BODY25),
)

_BLAZE = ("nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
          "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
          "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
          "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip",
          "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel",
          "right_heel", "left_foot_index", "right_foot_index")
_BLAZE_UNMODELLED = {"left_eye_inner", "left_eye_outer", "right_eye_inner", "right_eye_outer",
                     "mouth_left", "mouth_right", "left_pinky", "right_pinky", "left_index",
                     "right_index", "left_thumb", "right_thumb"}
BLAZEPOSE33 = KeypointLayout(
    "blazepose33", _BLAZE,
    tuple(None if k in _BLAZE_UNMODELLED else
          {"left_foot_index": "left_toe", "right_foot_index": "right_toe"}.get(k, k) for k in _BLAZE),
)

_OPENPOSE18 = ("nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow",
               "left_wrist", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
               "right_eye", "left_eye", "right_ear", "left_ear")
OPENPOSE18 = KeypointLayout("openpose18", _OPENPOSE18, _OPENPOSE18)
"""OpenPose's COCO model (18 points: COCO-17 plus the neck, in OpenPose's order)."""

LAYOUTS: dict[str, KeypointLayout] = {lay.name: lay for lay in (COCO17, BODY25, BLAZEPOSE33, OPENPOSE18)}


def neutral_pose(translation=(0.0, 0.0, 3.0), quaternion=(0.0, 1.0, 0.0, 0.0)) -> np.ndarray:
    """A (36,) pose with every angle 0 (the rest pose), by default 3 m in front of the camera."""
    h = np.zeros(POSE_DIM)
    h[ROOT_TRANSLATION] = translation
    h[ROOT_QUATERNION] = quaternion
    return h


def clamp_pose(h: np.ndarray) -> np.ndarray:
    """Clamp the 29 angles of poses ``h`` (..., 36) to Table 1 and renormalise the quaternion."""
    h = np.array(h, dtype=np.float64, copy=True)
    h[..., ANGLES] = np.clip(h[..., ANGLES], ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    q = h[..., ROOT_QUATERNION]
    h[..., ROOT_QUATERNION] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return h
