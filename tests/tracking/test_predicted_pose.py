"""The constant-velocity prediction of a pose across dropped frames, against hand computation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from swarmpose.body.kinematics import matrix_to_quaternion, quaternion_to_matrix
from swarmpose.body.skeleton import ANGLE_LIMITS
from swarmpose.tracking.search import MAX_PREDICTED_STEPS, predicted_pose


def _pose(x: float, yaw_deg: float, angle: float) -> np.ndarray:
    h = np.zeros(36)
    h[:3] = [x, 0.0, 3.0]
    h[3:7] = matrix_to_quaternion(Rotation.from_euler("y", yaw_deg, degrees=True).as_matrix())
    h[7:] = np.clip(angle, ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    return h


def test_a_pose_goes_on_as_it_came():
    before, previous = _pose(0.0, 10.0, 0.0), _pose(0.1, 20.0, 0.05)
    ahead = predicted_pose(previous, before, step_s=0.1, ahead_s=0.2)  # two more steps
    np.testing.assert_allclose(ahead[:3], [0.3, 0.0, 3.0], atol=1e-12)
    expected = np.clip(previous[7:] + 2 * (previous[7:] - before[7:]), ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    np.testing.assert_allclose(ahead[7:], expected, atol=1e-12)
    yaw = Rotation.from_matrix(quaternion_to_matrix(ahead[3:7])).as_euler("yxz", degrees=True)[0]
    assert abs(yaw - 40.0) < 1e-6
    assert abs(np.linalg.norm(ahead[3:7]) - 1) < 1e-12


def test_the_prediction_is_capped_and_never_goes_back():
    before, previous = _pose(0.0, 0.0, 0.0), _pose(0.1, 0.0, 0.0)
    far = predicted_pose(previous, before, step_s=0.1, ahead_s=10.0)
    assert abs(far[0] - 0.1 * (1 + MAX_PREDICTED_STEPS)) < 1e-12
    np.testing.assert_allclose(predicted_pose(previous, before, 0.1, -1.0), previous, atol=1e-12)
    np.testing.assert_allclose(predicted_pose(previous, before, 0.0, 0.1), previous, atol=1e-12)


def test_a_track_predicts_after_dropped_frames_and_a_live_one_after_every_step():
    """history.predicted: offline only after dropped frames; with ``every_step`` (a live frame) one camera
    frame on too, the walker 0.1 m and 10 degrees on again (hand computation)."""
    from swarmpose.tracking.history import TrackHistory

    history = TrackHistory()
    history.add(_pose(0.0, 10.0, 0.0), 0)
    assert history.predicted(33_333_333, 1.0, every_step=True) == [], "one pose: no motion to go on with"
    history.add(_pose(0.1, 20.0, 0.05), 33_333_333)
    assert history.predicted(66_666_667, 1.0) == [], "the next frame, offline"
    (seed,) = history.predicted(66_666_667, 1.0, every_step=True)
    np.testing.assert_allclose(seed[:3], [0.2, 0.0, 3.0], atol=1e-6)
    yaw = Rotation.from_matrix(quaternion_to_matrix(seed[3:7])).as_euler("yxz", degrees=True)[0]
    assert abs(yaw - 30.0) < 1e-4
    (after_a_drop,) = history.predicted(100_000_000, 2.0)
    np.testing.assert_allclose(after_a_drop[:3], [0.3, 0.0, 3.0], atol=1e-6)
