"""core.rotations and the tracker's rotation steps that used scipy's ``Rotation``, against scipy itself."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.core.rotations import matrix_to_quaternion, quaternion_multiply, rotvec_matrix
from swarmpose.core.world import transform_poses
from swarmpose.tracking.search import predicted_pose

RNG = np.random.default_rng(7)


def random_poses(n: int) -> np.ndarray:
    h = RNG.normal(size=(n, 36))
    h[:, 3:7] /= np.linalg.norm(h[:, 3:7], axis=1, keepdims=True)
    return h


@pytest.mark.parametrize("scale", [0.0, 1e-9, 1e-5, 0.3, 2.0, np.pi - 1e-6])
def test_rotation_vectors_give_scipys_matrices(scale):
    directions = RNG.normal(size=(50, 3))
    rotvec = directions / np.linalg.norm(directions, axis=1, keepdims=True) * scale * RNG.uniform(0.5, 1.0, (50, 1))
    np.testing.assert_allclose(rotvec_matrix(rotvec), Rotation.from_rotvec(rotvec).as_matrix(), atol=1e-12)


def test_quaternions_round_trip_and_compose_as_scipys():
    q = random_poses(200)[:, 3:7]
    xyzw = q[:, [1, 2, 3, 0]]
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(xyzw).as_matrix(), atol=1e-12)
    back = matrix_to_quaternion(quaternion_to_matrix(q))
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-12)  # the same rotation, +-q
    a, b = q[:100], q[100:]
    product = Rotation.from_quat(a[:, [1, 2, 3, 0]]) * Rotation.from_quat(b[:, [1, 2, 3, 0]])
    np.testing.assert_allclose(quaternion_to_matrix(quaternion_multiply(a, b)), product.as_matrix(), atol=1e-12)


def test_poses_moved_to_the_world_turn_as_scipy_composes_them():
    turn = Rotation.from_rotvec([0.3, -1.1, 0.4])
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = turn.as_matrix(), [0.5, 1.2, -2.0]
    h = random_poses(30)
    moved = transform_poses(t, h)
    expected = (turn * Rotation.from_quat(h[:, [4, 5, 6, 3]])).as_matrix()
    np.testing.assert_allclose(quaternion_to_matrix(moved[:, 3:7]), expected, atol=1e-12)
    np.testing.assert_allclose(moved[:, :3], h[:, :3] @ t[:3, :3].T + t[:3, 3], atol=1e-12)
    np.testing.assert_array_equal(moved[:, 7:], h[:, 7:])


@pytest.mark.parametrize("ahead", [0.0, 0.05, 0.1, 0.4])
def test_the_predicted_root_turns_on_as_scipy_extrapolates_it(ahead):
    before, previous = random_poses(2)
    previous[3:7] = (Rotation.from_rotvec([0.05, 0.2, -0.1]) * Rotation.from_quat(before[[4, 5, 6, 3]])).as_quat()[
        [3, 0, 1, 2]]
    out = predicted_pose(previous, before, 0.1, ahead)
    now = Rotation.from_quat(previous[[4, 5, 6, 3]])
    turn = now * Rotation.from_quat(before[[4, 5, 6, 3]]).inv()
    ratio = min(ahead / 0.1, 4.0)
    expected = (Rotation.from_rotvec(ratio * turn.as_rotvec()) * now).as_matrix()
    np.testing.assert_allclose(quaternion_to_matrix(out[3:7]), expected, atol=1e-10)
    assert out[3:7] @ previous[3:7] > 0  # stays in the previous pose's hemisphere


def test_zxy_euler_angles_are_scipys_and_rebuild_the_matrix():
    from swarmpose.core.rotations import zxy_euler_deg

    rot = Rotation.from_rotvec(RNG.normal(size=(300, 3)))
    angles = zxy_euler_deg(rot.as_matrix())
    np.testing.assert_allclose(angles, rot.as_euler("ZXY", degrees=True), atol=1e-9)
    locked = Rotation.from_euler("ZXY", [[30.0, 90.0, 20.0], [-70.0, -90.0, 45.0]], degrees=True)
    rebuilt = Rotation.from_euler("ZXY", zxy_euler_deg(locked.as_matrix()), degrees=True)
    np.testing.assert_allclose(rebuilt.as_matrix(), locked.as_matrix(), atol=1e-9)
