"""Forward kinematics and skinning against hand-computed cases and independent references."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import MAKEHUMAN, needs_assets
from scipy.spatial.transform import Rotation

from swarmpose.body.kinematics import (
    Rig,
    axis_angle_matrix,
    canonical_rotations,
    dual_quaternion_skinning,
    forward_kinematics,
    joint_rotations,
    linear_blend_skinning,
    matrix_to_quaternion,
    quaternion_to_matrix,
    shortest_arc,
    skinning_transforms,
    transform_points,
)
from swarmpose.body.skeleton import JOINT_INDEX, N_ANGLES, angle_offset, neutral_pose
from swarmpose.core.camera import project
from swarmpose.core.errors import ShapeError


def _arm_rig() -> Rig:
    """Root at the origin, upper arm from (0.2, 0, 0), forearm from (0.5, 0, 0), T-pose axes."""
    return Rig(parents=np.array([-1, 0, 1]), heads=np.array([[0, 0, 0], [0.2, 0, 0], [0.5, 0, 0.0]]),
               bone_joint=np.array([-1, JOINT_INDEX["left_shoulder"], JOINT_INDEX["left_elbow"]]),
               bone_fraction=np.array([0.0, 1.0, 1.0]), rest_frames=np.broadcast_to(np.eye(3), (3, 3, 3)).copy())


def _identity_pose() -> np.ndarray:
    return neutral_pose(translation=(0, 0, 0), quaternion=(1, 0, 0, 0))[None]


def test_two_bone_chain_matches_hand_computation():
    h = _identity_pose()
    h[0, 7 + angle_offset("left_shoulder") + 2] = -np.pi / 2  # yaw: swing the arm forward (+Z)
    h[0, 7 + angle_offset("left_elbow")] = -np.pi / 2  # flex the elbow another 90 degrees
    transforms = skinning_transforms(_arm_rig(), h)
    wrist = transform_points(np.array([2]), np.array([[0.8, 0, 0]]), transforms)[0, 0]
    elbow = transform_points(np.array([1]), np.array([[0.5, 0, 0]]), transforms)[0, 0]
    np.testing.assert_allclose(elbow, [0.2, 0, 0.3], atol=1e-12)
    np.testing.assert_allclose(wrist, [-0.1, 0, 0.3], atol=1e-12)


def test_root_translation_and_quaternion_apply_to_every_bone():
    h = _identity_pose()
    h[0, 0:3] = [1.0, 2.0, 3.0]
    h[0, 3:7] = [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0]  # 90 degrees about +Y: X -> -Z
    rot, pos = forward_kinematics(_arm_rig(), h)
    np.testing.assert_allclose(pos[0, 2], [1.0, 2.0, 3.0 - 0.5], atol=1e-12)
    np.testing.assert_allclose(rot[0, 2] @ [1, 0, 0], [0, 0, -1], atol=1e-12)


def test_quaternion_matrix_conventions_by_hand():
    s = np.sqrt(0.5)
    np.testing.assert_allclose(quaternion_to_matrix([s, s, 0, 0]), [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix([0, 1, 0, 0]), np.diag([1, -1, -1]), atol=1e-12)
    np.testing.assert_allclose(axis_angle_matrix([0, 0, 1], np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_matrix_to_quaternion_agrees_with_scipy():
    rng = np.random.default_rng(1)
    rots = Rotation.random(500, random_state=rng)
    q = matrix_to_quaternion(rots.as_matrix())
    ref = rots.as_quat()[:, [3, 0, 1, 2]]
    ref *= np.sign(ref[:, :1])
    np.testing.assert_allclose(q, ref, atol=1e-9)


def test_shortest_arc_turns_source_onto_target_with_least_angle():
    rng = np.random.default_rng(2)
    for _ in range(50):
        a, b = rng.normal(size=3), rng.normal(size=3)
        r = shortest_arc(a, b)
        np.testing.assert_allclose(r @ (a / np.linalg.norm(a)), b / np.linalg.norm(b), atol=1e-9)
        angle = np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))
        assert np.isclose(Rotation.from_matrix(r).magnitude(), angle, atol=1e-7)
    np.testing.assert_allclose(shortest_arc([1, 0, 0], [-1, 0, 0]) @ [1, 0, 0], [-1, 0, 0], atol=1e-12)


def _twist_transforms(angle: float) -> np.ndarray:
    t = np.zeros((1, 2, 3, 4))
    t[0, 0, :, :3] = np.eye(3)
    t[0, 1, :, :3] = axis_angle_matrix([1, 0, 0], angle)
    return t


def test_candy_wrapper_lbs_collapses_dqs_keeps_radius():
    ring = np.array([[0.0, 0.1 * np.cos(a), 0.1 * np.sin(a)] for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)])
    idx = np.tile([0, 1], (len(ring), 1))
    w = np.full((len(ring), 2), 0.5)
    transforms = _twist_transforms(np.pi)
    lbs = linear_blend_skinning(ring, idx, w, transforms)[0]
    dqs = dual_quaternion_skinning(ring, idx, w, transforms)[0]
    np.testing.assert_allclose(lbs, 0.0, atol=1e-12)  # (v + R_x(pi) v) / 2 = 0 for v in the YZ plane
    np.testing.assert_allclose(np.linalg.norm(dqs[:, 1:], axis=1), 0.1, atol=1e-12)
    # DQS blends to the half-angle rotation: 90 degrees about X.
    np.testing.assert_allclose(dqs, ring @ axis_angle_matrix([1, 0, 0], np.pi / 2).T, atol=1e-12)


def _tube(radius: float, length: float, rings: int, sections: int) -> trimesh.Trimesh:
    """A closed cylinder along X, centred on the origin, with ``rings`` rings of vertices."""
    xs = np.linspace(-length / 2, length / 2, rings)
    ang = np.linspace(0, 2 * np.pi, sections, endpoint=False)
    ring = np.stack([np.zeros(sections), radius * np.cos(ang), radius * np.sin(ang)], 1)
    verts = np.concatenate([ring + [x, 0, 0] for x in xs] + [[[xs[0], 0, 0], [xs[-1], 0, 0]]])
    faces = []
    for r in range(rings - 1):
        for s in range(sections):
            a, b = r * sections + s, r * sections + (s + 1) % sections
            faces += [[a, b, b + sections], [a, b + sections, a + sections]]
    c0, c1 = len(verts) - 2, len(verts) - 1
    last = (rings - 1) * sections
    for s in range(sections):
        faces += [[c0, (s + 1) % sections, s], [c1, last + s, last + (s + 1) % sections]]
    mesh = trimesh.Trimesh(verts, np.array(faces), process=False)
    trimesh.repair.fix_normals(mesh)
    return mesh


def test_dqs_preserves_volume_of_twisted_cylinder_lbs_does_not():
    cyl = _tube(radius=0.05, length=0.6, rings=121, sections=48)
    v = np.asarray(cyl.vertices)
    blend = np.clip((v[:, 0] + 0.15) / 0.3, 0, 1)  # 0 on the left end, 1 on the right end
    idx = np.tile([0, 1], (len(v), 1))
    w = np.stack([1 - blend, blend], 1)
    transforms = _twist_transforms(np.radians(150))
    vol0 = cyl.volume
    vol_lbs = trimesh.Trimesh(linear_blend_skinning(v, idx, w, transforms)[0], cyl.faces).volume
    vol_dqs = trimesh.Trimesh(dual_quaternion_skinning(v, idx, w, transforms)[0], cyl.faces).volume
    assert vol_lbs < 0.85 * vol0
    assert abs(vol_dqs - vol0) < 0.03 * vol0


def test_lbs_and_dqs_agree_for_rigid_influence_and_match_direct_transform():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3))
    t = np.zeros((5, 3, 3, 4))
    t[..., :3] = Rotation.random(15, random_state=rng).as_matrix().reshape(5, 3, 3, 3)
    t[..., 3] = rng.normal(size=(5, 3, 3))
    idx = np.zeros((40, 4), dtype=np.int64)
    idx[:, 0] = rng.integers(0, 3, 40)
    w = np.zeros((40, 4))
    w[:, 0] = 1
    per_vertex = t[:, idx[:, 0]]  # (P, V, 3, 4)
    direct = np.einsum("pvij,vj->pvi", per_vertex[..., :3], v) + per_vertex[..., 3]
    np.testing.assert_allclose(linear_blend_skinning(v, idx, w, t), direct, atol=1e-12)
    np.testing.assert_allclose(dual_quaternion_skinning(v, idx, w, t), direct, atol=1e-9)


def test_projection_by_hand():
    uv = project(np.array([[0.5, -0.25, 2.0]]), 500.0, 400.0, 320.0, 240.0)
    np.testing.assert_allclose(uv, [[320 + 125, 240 - 50]])


def test_bad_shapes_raise_with_both_shapes():
    with pytest.raises(ShapeError, match=r"\(3, 35\).*\(P, 36\)"):
        forward_kinematics(_arm_rig(), np.zeros((3, 35)))
    with pytest.raises(ShapeError, match="skin weights"):
        linear_blend_skinning(np.zeros((4, 3)), np.zeros((4, 2), int), np.zeros((4, 3)), np.zeros((1, 2, 3, 4)))


def test_bones_sharing_a_joint_compose_to_the_joint_rotation():
    """A spine split over k bones (fraction 1/k each) turns the chest exactly like one bone."""
    rng = np.random.default_rng(11)
    angles = rng.uniform(-1.0, 1.0, (20, N_ANGLES))
    spine = JOINT_INDEX["spine"]
    whole = joint_rotations(angles)[:, spine]
    for k in (2, 3, 5):
        frames = canonical_rotations(np.arange(-1, k), np.array([-1] + [spine] * k), np.array([0.0] + [1 / k] * k),
                                     np.broadcast_to(np.eye(3), (20, 3, 3)), angles)
        np.testing.assert_allclose(frames[:, -1], whole, atol=1e-9)


def test_batched_shortest_arc_handles_opposite_directions():
    src = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    dst = -src
    rots = shortest_arc(src, dst)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rots, src), dst, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rots), 1.0, atol=1e-12)


def test_non_finite_poses_and_zero_quaternions_are_rejected_by_row():
    h = np.tile(_identity_pose(), (4, 1))
    h[1, 9] = np.nan
    h[3, 3:7] = 0.0
    with pytest.raises(ShapeError, match=r"poses \[1, 3\]"):
        forward_kinematics(_arm_rig(), h)


def _loop_fk(rig: Rig, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics one joint DOF and one bone at a time (the textbook recursion, with
    scipy's rotations): the oracle for the batched implementation."""
    from swarmpose.body.skeleton import TRACKING_JOINTS

    def joint_matrix(joint, angles):  # E = R(compose[0]) R(compose[1]) ..., scipy's rotvecs
        kinds = [d.kind for d in joint.dofs]
        rot = np.eye(3)
        for kind in joint.compose:
            dof = joint.dofs[kinds.index(kind)]
            axis = np.asarray(dof.axis) / np.linalg.norm(dof.axis)
            rot = rot @ Rotation.from_rotvec(axis * angles[kinds.index(kind)]).as_matrix()
        return rot

    rots, heads = [], []
    for pose in h:
        joints = [joint_matrix(j, pose[7 + angle_offset(j.name):]) for j in TRACKING_JOINTS]
        frames = [Rotation.from_quat(pose[[4, 5, 6, 3]]).as_matrix()]
        for bone in range(1, len(rig.parents)):
            j, f = int(rig.bone_joint[bone]), float(rig.bone_fraction[bone])
            local = np.eye(3) if j < 0 else Rotation.from_rotvec(
                f * Rotation.from_matrix(joints[j]).as_rotvec()).as_matrix()
            frames.append(frames[rig.parents[bone]] @ local)
        rot = [w @ r.T for w, r in zip(frames, rig.rest_frames)]
        pos = [pose[:3]]
        for bone in range(1, len(rig.parents)):
            par = rig.parents[bone]
            pos.append(pos[par] + rot[par] @ (rig.heads[bone] - rig.heads[par]))
        rots.append(rot)
        heads.append(pos)
    return np.array(rots), np.array(heads)


@pytest.mark.parametrize("body", ["builtin", pytest.param("makehuman", marks=needs_assets)])
def test_batched_fk_matches_a_bone_by_bone_recursion(body):
    """The batched FK (every joint at once, the bones of one tree depth together) gives the
    bone-by-bone recursion's rotations and heads, on both bodies' rigs (shared joints with
    fractions, rigid bones), for one pose and for many."""
    from swarmpose.body.loader import load_body

    model = load_body("builtin" if body == "builtin" else f"makehuman:{MAKEHUMAN}", None)
    rng = np.random.default_rng(3)
    for count in (1, 9):
        h = np.tile(model.rest_pose((0.1, 0.2, 3.0), (0.0, 1.0, 0.0, 0.0)), (count, 1))
        h[:, 7:] += rng.normal(0.0, 0.5, (count, N_ANGLES))
        h[:, 3:7] = rng.normal(size=(count, 4))
        h[:, 3:7] /= np.linalg.norm(h[:, 3:7], axis=1, keepdims=True)
        rot, pos = forward_kinematics(model.rig, h)
        want_rot, want_pos = _loop_fk(model.rig, h)
        np.testing.assert_allclose(rot, want_rot, atol=1e-9)
        np.testing.assert_allclose(pos, want_pos, atol=1e-9)


def test_all_joints_at_once_equal_each_joint_composed_alone_bit_for_bit():
    """joint_rotations (every DOF in one call, the products padded with the identity) gives exactly
    compose_joint's matrices, joint by joint, on random angles: the same products in the same order."""
    from swarmpose.body.kinematics import compose_joint
    from swarmpose.body.skeleton import TRACKING_JOINTS

    angles = np.random.default_rng(4).uniform(-2.0, 2.0, (11, N_ANGLES))
    together = joint_rotations(angles)
    for ji, joint in enumerate(TRACKING_JOINTS):
        first = angle_offset(joint.name)
        alone = compose_joint(joint, angles[:, first:first + len(joint.dofs)])
        assert np.array_equal(together[:, ji], alone), joint.name
