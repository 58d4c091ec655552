"""The full joint set's orientations against two independent oracles.

(a) Each joint's frame equals the rotation composed by hand (scipy) from the pose vector's root
quaternion and angles, for poses retargeted from CMU motion capture: the axes and composition
orders are written out here from the skeleton's documentation (``swarmpose.body.skeleton``), not read
from the code's tables. (b) Finite differences of the joint positions: a bone's direction to its child,
expressed in the joint's frame, is the same in every pose (and near its documented T-pose axis), and a
small change of a joint's angles moves the child as the change of the joint's frame turns it.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP
from scipy.spatial.transform import Rotation

from swarmpose.body.joint_set import (
    BONE_AXES,
    EXTRA_JOINTS,
    SKELETON_JOINTS,
    SKELETON_LINKS,
    SKELETON_NAMES,
    posed_joints,
    skeleton_confidence,
)
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_NAMES, EVAL_JOINTS

CLIP = MOCAP / "animdrawings_cmu1_jumping_jacks.bvh"
X, Y, Z = np.eye(3)

# Each tracking joint's DOFs in multiplication order (axis, angle name), as skeleton.py documents them:
# roll about Z (forward), yaw about Y (up), pitch about X (left), hips and knees pitch about -X.
JOINT_STEPS = {
    "spine": ((Z, "spine.roll"), (X, "spine.pitch"), (Y, "spine.yaw")),
    "neck": ((Z, "neck.roll"), (X, "neck.pitch")),
    **{f"{s}_collar": ((Z, f"{s}_collar.roll"), (Y, f"{s}_collar.yaw")) for s in ("left", "right")},
    **{f"{s}_shoulder": ((Z, f"{s}_shoulder.roll"), (Y, f"{s}_shoulder.yaw"), (X, f"{s}_shoulder.pitch"))
       for s in ("left", "right")},
    **{f"{s}_elbow": ((Y, f"{s}_elbow.yaw"),) for s in ("left", "right")},
    **{f"{s}_hip": ((Z, f"{s}_hip.roll"), (-X, f"{s}_hip.pitch"), (Y, f"{s}_hip.yaw")) for s in ("left", "right")},
    **{f"{s}_knee": ((-X, f"{s}_knee.pitch"),) for s in ("left", "right")},
    **{f"{s}_ankle": ((Y, f"{s}_ankle.yaw"), (X, f"{s}_ankle.pitch")) for s in ("left", "right")},
}


def chain(name: str) -> tuple[str, ...]:
    """The tracking joints turning the bone of full-set joint ``name``, from the root down (a name
    ending in '/k' takes 1/k of that joint's rotation: the lowest of k bones sharing it)."""
    side = name.split("_")[0] if name.startswith(("left_", "right_")) else ""
    arm = ("spine", f"{side}_collar", f"{side}_shoulder", f"{side}_elbow")
    leg = (f"{side}_hip", f"{side}_knee", f"{side}_ankle")
    part = name.removeprefix(f"{side}_")
    return {"pelvis": (), "spine_navel": ("spine/k",), "spine_chest": ("spine",), "neck": ("spine", "neck/k"),
            "head": ("spine", "neck"), "nose": ("spine", "neck"), "eye": ("spine", "neck"), "ear": ("spine", "neck"),
            "clavicle": arm[:2], "shoulder": arm[:3], "elbow": arm, "wrist": arm, "hand": arm,
            "hip": leg[:1], "knee": leg[:2], "ankle": leg, "foot": leg}[part]


def by_hand(h: np.ndarray, name: str, shares: dict[str, int]) -> Rotation:
    """Joint ``name``'s frame at pose ``h`` (36,): the root quaternion, then each joint of its chain."""
    rot = Rotation.from_quat([h[4], h[5], h[6], h[3]])
    for link in chain(name):
        joint, _, share = link.partition("/")
        step = Rotation.identity()
        for axis, angle in JOINT_STEPS[joint]:
            step = step * Rotation.from_rotvec(axis * h[7 + ANGLE_NAMES.index(angle)])
        rot = rot * (Rotation.from_rotvec(step.as_rotvec() / shares[joint]) if share else step)
    return rot


@pytest.fixture(scope="module", params=["builtin", "makehuman"])
def body(request):
    if request.param == "makehuman":
        if not MAKEHUMAN.is_dir():
            pytest.skip(f"MakeHuman assets not found at {MAKEHUMAN}")
        return load_body(f"makehuman:{MAKEHUMAN}")
    return load_body("builtin")


@pytest.fixture(scope="module")
def poses(body) -> np.ndarray:
    """(P, 36) poses of a CMU jumping-jacks clip retargeted onto ``body``, turned to face a camera 3 m away."""
    if not CLIP.is_file():
        pytest.skip(f"motion capture not found at {CLIP}")
    from swarmpose.motion.retarget import load_motion

    motion = load_motion(str(CLIP), body)
    frames = np.linspace(0, len(motion) - 1, 16).astype(int)
    to_camera = Rotation.from_euler("x", 180, degrees=True) * Rotation.from_euler("y", 20, degrees=True)
    quats = (to_camera * Rotation.from_matrix(motion.root_rotation[frames])).as_quat()  # x y z w
    return np.concatenate([motion.root_offset[frames] + [0.0, 0.0, 3.0], quats[:, [3, 0, 1, 2]],
                           motion.angles[frames]], axis=1)


def test_orientations_are_the_rotations_composed_by_hand_from_the_mocap_pose(body, poses):
    shares = {"spine": len(body.bones_of_joint("spine")), "neck": len(body.bones_of_joint("neck"))}
    _, frames = posed_joints(body, poses)
    assert frames.shape == (len(poses), 28, 3, 3)
    assert np.ptp(poses[:, 7:], axis=0).max() > 1.0  # the clip moves the joints a lot
    for k, name in enumerate(SKELETON_NAMES):
        want = np.stack([by_hand(h, name, shares).as_matrix() for h in poses])
        np.testing.assert_allclose(frames[:, k], want, atol=1e-9, err_msg=name)


def test_positions_of_the_evaluation_joints_are_the_named_points_and_the_pelvis_the_root(body, poses):
    positions, _ = posed_joints(body, poses)
    points = body.posed_points(poses, EVAL_JOINTS)
    np.testing.assert_allclose(positions[:, [SKELETON_NAMES.index(n) for n in EVAL_JOINTS]], points, atol=1e-12)
    np.testing.assert_allclose(positions[:, SKELETON_NAMES.index("pelvis")], poses[:, :3], atol=1e-12)
    np.testing.assert_allclose(positions[:, SKELETON_NAMES.index("left_foot")],
                               body.posed_points(poses, ["left_toe"])[:, 0], atol=1e-12)


def rigid_links(body) -> list[tuple[str, str]]:
    """The links whose child rides on the parent joint's bone or is the pivot of a bone right below it
    (every link, except where a joint's rotation is shared by several bones between the two: on
    MakeHuman the spine's three bones below the chest and the neck's two below the head)."""
    split = {("spine_navel", "spine_chest")} if len(body.bones_of_joint("spine")) > 2 else set()
    split |= {("neck", "head")} if len(body.bones_of_joint("neck")) > 1 else set()
    return [link for link in SKELETON_LINKS if link not in split]


def test_a_bone_seen_from_its_joint_points_the_same_way_in_every_pose(body, poses):
    positions, frames = posed_joints(body, poses)
    links = rigid_links(body)
    assert len(links) >= 25
    for parent, child in links:
        j, c = SKELETON_NAMES.index(parent), SKELETON_NAMES.index(child)
        local = np.einsum("pji,pj->pi", frames[:, j], positions[:, c] - positions[:, j])  # W^T (child - joint)
        np.testing.assert_allclose(local, np.broadcast_to(local[0], local.shape), atol=1e-9,
                                   err_msg=f"{parent}->{child}")
        if parent in BONE_AXES and child == _first_child(parent):
            direction = local[0] / np.linalg.norm(local[0])
            part = parent.split("_")[-1]
            limit = AXIS_LIMIT_DEG.get(part, 12.0)
            angle = np.degrees(np.arccos(np.clip(direction @ BONE_AXES[parent], -1, 1)))
            assert angle <= limit, f"{parent}->{child}: {angle:.1f} degrees from its documented axis"


AXIS_LIMIT_DEG = {"shoulder": 1.0, "hip": 1.0, "knee": 1.0, "pelvis": 22.0, "head": 22.0, "ankle": 22.0}
"""How far a bone may lie from its documented T-pose axis (``BONE_AXES``), degrees; 12 for the others."""


def _first_child(name: str) -> str:
    return next(c for p, c in SKELETON_LINKS if p == name)


@pytest.mark.parametrize("joint", ["left_shoulder", "right_elbow", "left_hip", "right_knee", "left_collar"])
def test_a_small_change_of_a_joints_angles_moves_its_child_as_its_frame_turns(body, poses, joint):
    """Central differences: the child's velocity is omega x (child - pivot), omega the rate of turn of the
    joint's frame; the pivot stays put. Positions from the body's named points (``posed_points``)."""
    pivot, child = {"left_shoulder": ("left_shoulder", "left_elbow"), "right_elbow": ("right_elbow", "right_wrist"),
                    "left_hip": ("left_hip", "left_knee"), "right_knee": ("right_knee", "right_ankle"),
                    "left_collar": ("left_clavicle", "left_shoulder")}[joint]
    rng = np.random.default_rng(3)
    k = SKELETON_NAMES.index(pivot)
    eps = 1e-6
    for h in poses[::4]:
        delta = np.zeros(36)
        for n, name in enumerate(ANGLE_NAMES):
            if name.startswith(f"{joint}."):
                delta[7 + n] = rng.uniform(-1, 1)
        ahead, back = h + eps * delta, h - eps * delta
        points = body.posed_points(np.stack([ahead, back, h]), [pivot, child])
        _, frames = posed_joints(body, np.stack([ahead, back]))
        omega = Rotation.from_matrix(frames[0, k] @ frames[1, k].T).as_rotvec() / (2 * eps)
        velocity = (points[0, 1] - points[1, 1]) / (2 * eps)
        np.testing.assert_allclose(points[0, 0], points[1, 0], atol=1e-12)  # the pivot does not move
        np.testing.assert_allclose(velocity, np.cross(omega, points[2, 1] - points[2, 0]), atol=1e-6)
        assert np.linalg.norm(velocity) > 0.01  # the change does move the child (m per unit of delta)


def test_the_full_set_names_azure_joints_and_takes_its_confidence_from_the_evaluation_joints():
    assert len(SKELETON_NAMES) == 28 and set(EVAL_JOINTS) <= set(SKELETON_NAMES) and len(EXTRA_JOINTS) == 14
    azure = {j.name: j.azure for j in SKELETON_JOINTS}
    assert (azure["pelvis"], azure["spine_navel"], azure["left_clavicle"], azure["right_foot"]) == (
        "PELVIS", "SPINE_NAVEL", "CLAVICLE_LEFT", "FOOT_RIGHT")
    confidence = np.linspace(0.0, 1.0, 14)
    full = dict(zip(SKELETON_NAMES, skeleton_confidence(confidence)))
    given = dict(zip(EVAL_JOINTS, confidence))
    assert all(full[n] == given[n] for n in EVAL_JOINTS)
    assert full["left_hand"] == given["left_wrist"] and full["nose"] == given["head"]
    assert full["pelvis"] == pytest.approx((given["left_hip"] + given["right_hip"]) / 2)


BVH_JOINTS = {"pelvis": "Hips", "left_shoulder": "LeftShoulder", "right_shoulder": "RightShoulder",
              "left_elbow": "LeftElbow", "right_elbow": "RightElbow", "left_hip": "LeftHip", "right_hip": "RightHip",
              "left_knee": "LeftKnee", "right_knee": "RightKnee"}
"""Our joints and the CMU 3dsMax joints (the clips below) whose global rotation each one's frame follows."""
HINGE_MEDIAN_DEG = 8.0
"""The elbows are hinges on the body: the forearm's twist about its bone in the capture stays out
of the elbow's frame (measured medians 3-7 degrees)."""


@pytest.mark.parametrize("clip", ["animdrawings_cmu1_jumping_jacks.bvh", "bvh11_131_01.bvh"])
def test_a_joints_frame_turns_as_the_captured_joint_did(clip):
    """Against the BVH's own rotations: over 16 frames of a clip, how far each joint's frame turned
    since the first frame equals how far the clip's joint turned (the angle of the change, which
    does not depend on how the file's axes map onto the body's), within 1 degree at the median (the
    elbows: HINGE_MEDIAN_DEG)."""
    from swarmpose.motion.bvh import read_bvh
    from swarmpose.motion.retarget import load_motion

    path = MOCAP / clip
    if not path.is_file():
        pytest.skip(f"motion capture not found at {path}")
    body = load_body("builtin")
    motion, captured = load_motion(str(path), body), read_bvh(str(path))
    frames = np.linspace(0, len(motion) - 1, 16).astype(int)
    quats = Rotation.from_matrix(motion.root_rotation[frames]).as_quat()
    poses = np.concatenate([motion.root_offset[frames], quats[:, [3, 0, 1, 2]], motion.angles[frames]], axis=1)
    _, ours = posed_joints(body, poses)
    theirs, _ = captured.global_transforms()
    for name, bvh_name in BVH_JOINTS.items():
        mine, bone = ours[:, SKELETON_NAMES.index(name)], theirs[frames, captured.joint_names.index(bvh_name)]
        turned = Rotation.from_matrix(mine @ mine[0].T).magnitude()
        captured_turn = Rotation.from_matrix(bone @ bone[0].T).magnitude()
        assert np.degrees(captured_turn.max()) > 10, name  # the clip moves it
        error = np.degrees(np.median(np.abs(turned - captured_turn)))
        assert error <= (HINGE_MEDIAN_DEG if name.endswith("elbow") else 1.0), (name, error)
