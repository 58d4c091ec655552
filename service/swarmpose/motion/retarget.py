"""Retarget BVH motion capture onto a body's tracking skeleton.

Skeleton families recognised by their joint names (:mod:`swarmpose.motion.joint_map`): CMU
MotionBuilder and Mixamo-like (LeftArm, LeftUpLeg, ...), CMU 3dsMax (LeftCollar, LeftShoulder =
upper arm, LeftHip, ...), the old MakeHuman skeleton (UpArm_L, LoLeg_L, ...), the Daz-named CMU
release (lCollar, lShldr, lThigh, ...) and CMU's ASF names (lclavicle, lhumerus, lfemur, ...);
any other naming through a user's joint map (:class:`ReadOptions`).

Method, per frame (vectorised over frames, a loop over the 14 joints):

1. The file's up axis and units are detected or stated (:mod:`swarmpose.motion.clip_frame`);
   the reference pose is the zero pose, or the first frame, whichever stands upright along
   the up axis. Body axes from it: X = left hip - right hip, Y = pelvis -> neck, Z = X x Y;
   angles are measured there, and the root's rotation and motion are then turned into the
   world, whose Y is the up axis (so the floor stays level however the reference leans).
   Lengths are only used as ratios (leg length of the body over that of the clip), so
   units cancel.
2. Each tracking segment's canonical world rotation (relative to the T-pose) is the
   driving mocap joint's global rotation composed with the shortest arc from the T-pose
   direction to the clip's zero-pose direction, then turned minimally so the segment
   points exactly where the clip's joints are: direction from positions, twist from the
   mocap rotation.
3. Rotations relative to the already-fitted parent are decomposed into the joint's DOFs
   (:func:`swarmpose.body.joint_angles.decompose_joint`) and clamped to Table 1. What
   the skeleton cannot do (limits, missing DOFs) is lost, as it is for the tracker.

The angles mean the same on every body (zero = T-pose); only the root motion is scaled
to the body's leg length.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from swarmpose.body.joint_angles import TOPOLOGICAL_ORDER, clamp_joint, decompose_joint, joint_rotation
from swarmpose.body.kinematics import axis_angle_matrix, shortest_arc
from swarmpose.body.skeleton import N_ANGLES, TRACKING_JOINTS, angle_offset
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import MotionError
from swarmpose.motion.bvh import BvhClip, read_bvh
from swarmpose.motion.clip_frame import ClipFrame, axis_vector, clip_frame, detect_up, parse_units, parse_up
from swarmpose.motion.joint_map import MAP_HELP, JointMap, Roles, family_map, resolve_roles
from swarmpose.motion.sequence import Motion

# tracking joint -> (driving joint, pivot, child) by joint-map key; sided names get the side.
log = logging.getLogger(__name__)

_TRACKING_SEGMENTS = {
    "collar": ("collar", "collar", "shoulder"),
    "shoulder": ("shoulder", "shoulder", "elbow"),
    "elbow": ("elbow", "elbow", "wrist"),
    "hip": ("hip", "hip", "knee"),
    "knee": ("knee", "knee", "ankle"),
    "ankle": ("ankle", "ankle", "toe"),
}
_UPRIGHT_COS = np.cos(np.radians(45.0))


@dataclass(frozen=True)
class ReadOptions:
    """How to read a clip. joint_map: the names to use (None: recognise a known family);
    units, up: as the user states them (None: the map file's, else detected); see
    :mod:`swarmpose.motion.clip_frame`."""

    joint_map: JointMap | None = None
    units: str | None = None
    up: str | None = None


@dataclass(frozen=True)
class ClipReading:
    """A clip's skeleton as retargeting reads it.

    roles: the joint of every map key (the toes may be End Sites appended after the clip's
    joints). frame: its up axis and units. rotations (N, K, 3, 3), positions (N, K, 3): global
    transforms, file units, K >= J with the End-Site toes. reference_positions (K, 3),
    reference_rotations (K, 3, 3): the standing pose the motion is measured from (the zero pose,
    or the first frame when the zero pose does not stand upright along the up axis).
    """

    roles: Roles
    frame: ClipFrame
    rotations: np.ndarray
    positions: np.ndarray
    reference_positions: np.ndarray
    reference_rotations: np.ndarray


def _frame_from(lateral: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) whose columns are X = ``lateral``, Y = ``up`` made orthogonal to it, Z = X x Y."""
    x = lateral / np.linalg.norm(lateral)
    y = up - (up @ x) * x
    y = y / np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _level_frame(lateral: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) whose columns are X = ``lateral`` levelled (its ``up`` part removed),
    Y = ``up`` (a unit vector) exactly, Z = X x Y."""
    x = lateral - (lateral @ up) * up
    x = x / np.linalg.norm(x)
    return np.stack([x, up, np.cross(x, up)], axis=-1)


def _is_standing(pose: np.ndarray, idx: dict[str, int], up: np.ndarray) -> bool:
    """True when joint positions (K, 3) look like an upright person along ``up`` (3,): hips apart,
    the torso across them and within 45 degrees of ``up``."""
    lateral = pose[idx["left_hip"]] - pose[idx["right_hip"]]
    torso = pose[idx["neck"]] - pose[idx["pelvis"]]
    ln, un = np.linalg.norm(lateral), np.linalg.norm(torso)
    return bool(ln > 1e-6 * max(un, 1.0) and un > 1e-9 and abs(lateral @ torso) < 0.5 * ln * un
                and torso @ up > _UPRIGHT_COS * un)


def read_clip(clip: BvhClip, options: ReadOptions | None = None) -> ClipReading:
    """The clip's roles, up axis, units and reference pose (see :class:`ClipReading`).

    Raises MotionError when its joints cannot be mapped (naming those it lacks), when a foot has
    neither a toe joint nor an End Site, or when neither its zero pose nor its first frame stands
    upright along its up axis.
    """
    options = options or ReadOptions()
    joint_map = options.joint_map or family_map(clip.joint_names, clip.name)
    roles = resolve_roles(clip.joint_names, clip.parents, joint_map, clip.name)
    idx = dict(roles.index)
    rot_f, pos_f = clip.global_transforms()
    rest = clip.rest_positions()
    ends = [rest[j] + e for j, e in clip.end_offsets.items()]
    ends_0 = [pos_f[0, j] + rot_f[0, j] @ e for j, e in clip.end_offsets.items()]
    for side in ("left", "right"):  # feet without a toe joint: use the foot's end site
        if f"{side}_toe" not in idx:
            foot = idx[f"{side}_ankle"]
            if foot not in clip.end_offsets:
                raise MotionError(f"BVH {clip.name}: no toe joint or end site below the {side} ankle; "
                                  f"map {side}_toe to a joint below it ({MAP_HELP})")
            end = pos_f[:, foot] + rot_f[:, foot] @ clip.end_offsets[foot]
            pos_f = np.concatenate([pos_f, end[:, None]], axis=1)
            rot_f = np.concatenate([rot_f, rot_f[:, foot, None]], axis=1)
            rest = np.concatenate([rest, (rest[foot] + clip.end_offsets[foot])[None]])
            idx[f"{side}_toe"] = pos_f.shape[1] - 1
    where = f"BVH {clip.name}"
    stated_up = options.up or joint_map.up
    stated_units = options.units or joint_map.units
    up = (parse_up(stated_up, where) if stated_up else
          detect_up(pos_f[:, idx["head"]], pos_f[:, idx["left_ankle"]], pos_f[:, idx["right_ankle"]]))
    if _is_standing(rest, idx, axis_vector(up)):
        ref_pos, ref_rot, points = rest, np.broadcast_to(np.eye(3), rot_f.shape[1:]), [rest, *ends]
    elif _is_standing(pos_f[0], idx, axis_vector(up)):
        ref_pos, ref_rot, points = pos_f[0], rot_f[0], [pos_f[0], *ends_0]
    else:
        how = "stated" if stated_up else "where its head is above its feet in most frames"
        raise MotionError(f"{where}: neither its zero pose nor its first frame is a person standing upright along "
                          f"{up} ({how}); state its up axis (?up=y or ?up=z)")
    frame = clip_frame(np.vstack(points), up, bool(stated_up),
                       parse_units(stated_units, where) if stated_units else None, where)
    return ClipReading(Roles(idx, roles.source), frame, rot_f, pos_f, ref_pos, ref_rot)


def retarget(clip: BvhClip, body: SkinnedBody, fps: float | None = None, options: ReadOptions | None = None) -> Motion:
    """The clip as a :class:`Motion` of ``body``'s tracking skeleton, resampled to ``fps``.

    The reference pose is the clip's zero pose, or its first frame when the zero pose is
    not an upright person (some exporters put every offset along one axis); see :func:`read_clip`.
    """
    if fps is not None:
        clip = clip.resample(fps)
    reading = read_clip(clip, options)
    idx = reading.roles.index
    rot_f, pos_f = reading.rotations, reading.positions
    rest, ref_rot = reading.reference_positions, reading.reference_rotations
    log.info("%s: %s skeleton, %s up (%s), %s (%s), %.2f m tall", clip.name, reading.roles.source, reading.frame.up,
             "stated" if reading.frame.up_stated else "detected", reading.frame.units,
             "stated" if reading.frame.units_stated else "detected", reading.frame.height_m)
    # File axes -> the reference's body axes (X left, Y pelvis -> neck, Z forward), where angles are
    # measured; ``level`` turns those into the world's (Y the file's up axis). Units cancel below.
    lateral = rest[idx["left_hip"]] - rest[idx["right_hip"]]
    conv = _frame_from(lateral, rest[idx["neck"]] - rest[idx["pelvis"]]).T
    level = _level_frame(lateral, reading.frame.up_vector).T @ conv.T
    delta = conv @ (rot_f @ np.swapaxes(ref_rot, -1, -2)) @ conv.T  # (N, J, 3, 3) rotation from the reference
    gpos = pos_f @ conv.T  # (N, J, 3)
    ref = rest @ conv.T
    n = len(gpos)

    # Root: the pelvis rotation from the reference, turned so its X axis runs along the hips.
    w_root = delta[:, idx["pelvis"]]
    w_root = shortest_arc(w_root[:, :, 0], gpos[:, idx["left_hip"]] - gpos[:, idx["right_hip"]]) @ w_root

    segments: dict[str, tuple[str, str, str]] = {"spine": ("spine_top", "spine_base", "neck"),
                                                  "neck": ("head", "neck", "head")}
    for side in ("left", "right"):
        for joint, (drv, piv, chi) in _TRACKING_SEGMENTS.items():
            segments[f"{side}_{joint}"] = (f"{side}_{drv}", f"{side}_{piv}", f"{side}_{chi}")

    achieved: dict[str, np.ndarray] = {"root": w_root}
    angles = np.zeros((n, N_ANGLES))
    for j in TOPOLOGICAL_ORDER:
        joint = TRACKING_JOINTS[j]
        drv, piv, chi = segments[joint.name]
        tpose_dir = np.asarray(joint.rest_direction)
        ref_dir = ref[idx[chi]] - ref[idx[piv]]
        if np.linalg.norm(ref_dir) < 1e-9:
            continue  # e.g. a head joint at the neck: nothing to measure, keep the angles at 0
        if joint.name.endswith("ankle"):
            # A foot is flat in the reference pose: T-pose foot -> the reference foot levelled,
            # then the foot's own rotation (ankle -> toe points down even when the sole is flat).
            ref_dir = ref_dir - ref_dir[1] * np.array([0.0, 1.0, 0.0])
            w_des = delta[:, idx[drv]] @ shortest_arc(tpose_dir, ref_dir)
        else:
            # T-pose segment -> reference segment -> current segment; the twist from the
            # driving joint's rotation, the direction exactly from the joint positions.
            w_des = delta[:, idx[drv]] @ shortest_arc(tpose_dir, ref_dir)
            w_des = shortest_arc(w_des @ tpose_dir, gpos[:, idx[chi]] - gpos[:, idx[piv]]) @ w_des
        parent = achieved[joint.parent]
        ang = clamp_joint(j, decompose_joint(j, np.swapaxes(parent, -1, -2) @ w_des))
        start = angle_offset(joint.name)
        angles[:, start:start + len(joint.dofs)] = ang
        achieved[joint.name] = parent @ joint_rotation(j, ang)

    # Root motion relative to the first frame, scaled by leg length (synth floors the sequence).
    def leg(p: np.ndarray) -> float:
        return float(np.linalg.norm(p[idx["left_knee"]] - p[idx["left_hip"]])
                     + np.linalg.norm(p[idx["left_ankle"]] - p[idx["left_knee"]]))

    body_leg = float(np.linalg.norm(body.point("left_knee") - body.point("left_hip"))
                     + np.linalg.norm(body.point("left_ankle") - body.point("left_knee")))
    scale = body_leg / max(leg(ref), 1e-9)
    # In the world the floor is level however the reference's torso leans (else a long walk climbs or sinks).
    offset = (gpos[:, idx["pelvis"]] - gpos[0, idx["pelvis"]]) @ level.T
    w_root = level @ w_root
    fwd = w_root[0, :, 2]  # face +Z at the first frame
    turn = axis_angle_matrix((0.0, 1.0, 0.0), -np.arctan2(fwd[0], fwd[2]))
    return Motion(name=clip.name, fps=clip.fps, root_offset=scale * offset @ turn.T,
                  root_rotation=turn @ w_root, angles=angles)


def load_motion(path: str, body: SkinnedBody, fps: float | None = None, options: ReadOptions | None = None) -> Motion:
    """Read a BVH file and retarget it onto ``body`` (see :func:`retarget`)."""
    return retarget(read_bvh(path), body, fps, options)
