"""Retarget BVH motion capture onto a body's tracking skeleton.

Supported skeleton families (recognised by their joint names): CMU MotionBuilder
(LowerBack, LeftArm, LeftUpLeg, ...), CMU 3dsMax (LeftCollar, LeftShoulder = upper arm,
LeftHip, LeftKnee, ...), Mixamo-like (Spine..Spine3, LeftArm, LeftUpLeg; with or without
fingers) and the old MakeHuman skeleton (UpArm_L, LoLeg_L, ...).

Method, per frame (vectorised over frames, a loop over the 14 joints):

1. The file's axes and units are read off its zero pose: X = left hip - right hip,
   Y = pelvis -> neck (so Y-up and Z-up files both work), Z = X x Y; lengths are only
   used as ratios (leg length of the body over that of the clip), so units cancel.
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

import numpy as np

from swarmpose.body.joint_angles import TOPOLOGICAL_ORDER, clamp_joint, decompose_joint, joint_rotation
from swarmpose.body.kinematics import axis_angle_matrix, shortest_arc
from swarmpose.body.skeleton import N_ANGLES, TRACKING_JOINTS, angle_offset
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import MotionError
from swarmpose.motion.bvh import BvhClip, read_bvh
from swarmpose.motion.sequence import Motion

_SEGMENT_NAMES = {
    # role: (CMU MotionBuilder / Mixamo, CMU 3dsMax, old MakeHuman); "{S}" = Left/Right, "{s}" = L/R
    "collar": ("{S}Shoulder", "{S}Collar", "Clavicle_{s}"),
    "upper_arm": ("{S}Arm", "{S}Shoulder", "UpArm_{s}"),
    "forearm": ("{S}ForeArm", "{S}Elbow", "LoArm_{s}"),
    "hand": ("{S}Hand", "{S}Wrist", "Hand_{s}"),
    "thigh": ("{S}UpLeg", "{S}Hip", "UpLeg_{s}"),
    "shin": ("{S}Leg", "{S}Knee", "LoLeg_{s}"),
    "foot": ("{S}Foot", "{S}Ankle", "Foot_{s}"),
    "toe": ("{S}ToeBase", "{S}Toe", "Toe_{s}"),
}
_FAMILIES = ("mb", "3dsmax", "makehuman")

# tracking joint -> (driving segment, pivot segment, child segment); sided names get the side.
_TRACKING_SEGMENTS = {
    "collar": ("collar", "collar", "upper_arm"),
    "shoulder": ("upper_arm", "upper_arm", "forearm"),
    "elbow": ("forearm", "forearm", "hand"),
    "hip": ("thigh", "thigh", "shin"),
    "knee": ("shin", "shin", "foot"),
    "ankle": ("foot", "foot", "toe"),
}


def _family(names: set[str]) -> int:
    if "LeftCollar" in names:
        return _FAMILIES.index("3dsmax")
    if "UpArm_L" in names:
        return _FAMILIES.index("makehuman")
    if "LeftArm" in names:
        return _FAMILIES.index("mb")
    raise MotionError("unknown BVH skeleton: expected CMU (LeftArm/LeftCollar), Mixamo (LeftArm) "
                      f"or MakeHuman (UpArm_L) joint names, found {sorted(names)[:12]}...")


class _Roles:
    """Indices of the clip's joints for every role the retargeting needs."""

    def __init__(self, clip: BvhClip):
        names = list(clip.joint_names)
        fam = _family(set(names))
        self.index: dict[str, int] = {}
        missing = []
        for role, patterns in _SEGMENT_NAMES.items():
            for side, s in (("left", "L"), ("right", "R")):
                name = patterns[fam].format(S=side.capitalize(), s=s)
                if name in names:
                    self.index[f"{side}_{role}"] = names.index(name)
                elif role != "toe":
                    missing.append(name)
        for role, name in (("head", "Head"), ("neck", "Neck" if fam != 1 else "lowerneck")):
            if name in names:
                self.index[role] = names.index(name)
            else:
                missing.append(name)
        if missing:
            raise MotionError(f"BVH {clip.name}: joints {missing} not found; the clip's skeleton is not one of "
                              "the supported families (CMU, Mixamo, MakeHuman)")
        # The pelvis is the common ancestor of both thighs; the spine runs from it to the neck.
        chain = self._ancestors(clip, self.index["neck"])
        left = set(self._ancestors(clip, self.index["left_thigh"]))
        pelvis = next(j for j in chain if j in left)
        self.index["pelvis"] = pelvis
        spine = chain[:chain.index(pelvis)][::-1]  # pelvis-exclusive, bottom -> top, ends at the neck
        if len(spine) < 2:
            raise MotionError(f"BVH {clip.name}: no spine joint between the pelvis and the neck")
        self.index["spine_base"] = spine[0]
        self.index["spine_top"] = spine[-2]

    @staticmethod
    def _ancestors(clip: BvhClip, j: int) -> list[int]:
        out = []
        while j >= 0:
            out.append(j)
            j = int(clip.parents[j])
        return out


def _frame_from(lateral: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotations (..., 3, 3) whose columns are X = lateral, Y = up (orthogonalised), Z = X x Y."""
    x = lateral / np.linalg.norm(lateral, axis=-1, keepdims=True)
    y = up - np.sum(up * x, axis=-1, keepdims=True) * x
    y /= np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _is_standing(rest: np.ndarray, idx: dict[str, int]) -> bool:
    """True when joint positions (J, 3) look like an upright person: hips apart, torso across them."""
    lateral = rest[idx["left_thigh"]] - rest[idx["right_thigh"]]
    up = rest[idx["neck"]] - rest[idx["pelvis"]]
    ln, un = np.linalg.norm(lateral), np.linalg.norm(up)
    return bool(ln > 1e-6 * max(un, 1.0) and un > 1e-9 and abs(lateral @ up) < 0.5 * ln * un)


def retarget(clip: BvhClip, body: SkinnedBody, fps: float | None = None) -> Motion:
    """The clip as a :class:`Motion` of ``body``'s tracking skeleton, resampled to ``fps``.

    The reference pose is the clip's zero pose, or its first frame when the zero pose is
    not an upright person (some exporters put every offset along one axis).
    """
    if fps is not None:
        clip = clip.resample(fps)
    idx = _Roles(clip).index
    rot_f, pos_f = clip.global_transforms()
    rest = clip.rest_positions()
    for side in ("left", "right"):  # feet without a toe joint: use the foot's end site
        if f"{side}_toe" not in idx:
            foot = idx[f"{side}_foot"]
            if foot not in clip.end_offsets:
                raise MotionError(f"BVH {clip.name}: no toe joint or end site below the {side} foot")
            end = pos_f[:, foot] + rot_f[:, foot] @ clip.end_offsets[foot]
            pos_f = np.concatenate([pos_f, end[:, None]], axis=1)
            rot_f = np.concatenate([rot_f, rot_f[:, foot, None]], axis=1)
            rest = np.concatenate([rest, (rest[foot] + clip.end_offsets[foot])[None]])
            idx[f"{side}_toe"] = pos_f.shape[1] - 1
    if _is_standing(rest, idx):
        ref_rot = np.broadcast_to(np.eye(3), rot_f.shape[1:])
    else:
        rest, ref_rot = pos_f[0], rot_f[0]
        if not _is_standing(rest, idx):
            raise MotionError(f"BVH {clip.name}: neither its zero pose nor its first frame is an upright "
                              "person; cannot tell its up axis")
    # File axes -> world (X left, Y up, Z forward) from the reference pose; units cancel below.
    conv = _frame_from(rest[idx["left_thigh"]] - rest[idx["right_thigh"]], rest[idx["neck"]] - rest[idx["pelvis"]]).T
    delta = conv @ (rot_f @ np.swapaxes(ref_rot, -1, -2)) @ conv.T  # (N, J, 3, 3) rotation from the reference
    gpos = pos_f @ conv.T  # (N, J, 3)
    ref = rest @ conv.T
    n = len(gpos)

    # Root: the pelvis rotation from the reference, turned so its X axis runs along the hips.
    w_root = delta[:, idx["pelvis"]]
    w_root = shortest_arc(w_root[:, :, 0], gpos[:, idx["left_thigh"]] - gpos[:, idx["right_thigh"]]) @ w_root

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
        return float(np.linalg.norm(p[idx["left_shin"]] - p[idx["left_thigh"]])
                     + np.linalg.norm(p[idx["left_foot"]] - p[idx["left_shin"]]))

    body_leg = float(np.linalg.norm(body.point("left_knee") - body.point("left_hip"))
                     + np.linalg.norm(body.point("left_ankle") - body.point("left_knee")))
    scale = body_leg / max(leg(ref), 1e-9)
    offset = gpos[:, idx["pelvis"]] - gpos[0, idx["pelvis"]]
    fwd = w_root[0, :, 2]  # face +Z at the first frame
    turn = axis_angle_matrix((0.0, 1.0, 0.0), -np.arctan2(fwd[0], fwd[2]))
    return Motion(name=clip.name, fps=clip.fps, root_offset=scale * offset @ turn.T,
                  root_rotation=turn @ w_root, angles=angles)


def load_motion(path: str, body: SkinnedBody, fps: float | None = None) -> Motion:
    """Read a BVH file and retarget it onto ``body`` (see :func:`retarget`)."""
    return retarget(read_bvh(path), body, fps)
