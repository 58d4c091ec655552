"""The pose fitted to target points (inverse kinematics) against poses whose points are known."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.joint_fit import fit_pose_to_points
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLES, EVAL_JOINTS, neutral_pose


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


def test_the_points_of_a_known_pose_are_reached_from_a_disturbed_start(body):
    rng = np.random.default_rng(3)
    truth = neutral_pose()
    truth[ANGLES] = ANGLE_LIMITS[:, 0] + rng.uniform(0.2, 0.8, len(ANGLE_LIMITS)) * np.diff(ANGLE_LIMITS, axis=1)[:, 0]
    targets = body.posed_points(truth[None], EVAL_JOINTS)[0]
    start = truth.copy()
    start[:3] += (0.03, -0.02, 0.04)
    start[ANGLES] = np.clip(start[ANGLES] + rng.normal(0.0, 0.1, len(ANGLE_LIMITS)), ANGLE_LIMITS[:, 0],
                            ANGLE_LIMITS[:, 1])
    before = np.linalg.norm(body.posed_points(start[None], EVAL_JOINTS)[0] - targets, axis=1).mean()
    fit = fit_pose_to_points(body, start, EVAL_JOINTS, targets, max_evaluations=50)
    after = np.linalg.norm(body.posed_points(fit[None], EVAL_JOINTS)[0] - targets, axis=1).mean()
    assert before > 0.03 and after < 0.003, (before, after)
    assert np.array_equal(fit[3:7], start[3:7])  # the root rotation is held
    assert np.all(fit[ANGLES] >= ANGLE_LIMITS[:, 0] - 1e-9) and np.all(fit[ANGLES] <= ANGLE_LIMITS[:, 1] + 1e-9)


def test_a_target_beyond_the_limits_stops_at_them(body):
    start = neutral_pose()
    wrist = EVAL_JOINTS.index("left_wrist")
    at_start = body.posed_points(start[None], EVAL_JOINTS)[0]
    targets = at_start.copy()
    targets[wrist] += (0.0, 0.0, -2.0)  # two metres in front of the body: no pose reaches it
    fit = fit_pose_to_points(body, start, EVAL_JOINTS, targets)
    assert np.all(fit[ANGLES] >= ANGLE_LIMITS[:, 0] - 1e-9) and np.all(fit[ANGLES] <= ANGLE_LIMITS[:, 1] + 1e-9)
    points = body.posed_points(fit[None], EVAL_JOINTS)[0]
    assert np.linalg.norm(points[wrist] - targets[wrist]) < 2.0 - 0.2  # the arm reached towards it


def test_targets_of_the_wrong_shape_or_not_finite_are_refused(body):
    targets = body.posed_points(neutral_pose()[None], EVAL_JOINTS)[0]
    with pytest.raises(ValueError, match="finite"):
        fit_pose_to_points(body, neutral_pose(), EVAL_JOINTS, targets[:-1])
    targets[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        fit_pose_to_points(body, neutral_pose(), EVAL_JOINTS, targets)


def test_a_start_beyond_its_limits_is_kept_where_it_is_already_right(body):
    start = neutral_pose()
    start[ANGLES][0] = ANGLE_LIMITS[0, 1] + 0.3  # a pose given from elsewhere, past a limit
    targets = body.posed_points(start[None], EVAL_JOINTS)[0]
    fit = fit_pose_to_points(body, start, EVAL_JOINTS, targets)
    assert fit[ANGLES][0] == pytest.approx(start[ANGLES][0], abs=1e-6)
