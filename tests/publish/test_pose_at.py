"""A frame message's poses moved on by their velocities, against hand computation."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.publish.pose_at import HORIZON_S, extrapolate, pose_at


def _message(received_ns: int) -> dict:
    joints = {name: {"position_m": [float(k), 0.0, 2.0], "pixel": [0.0, 0.0], "confidence": 1.0,
                     "velocity_m_s": [1.0, -0.5, 0.0]} for k, name in enumerate(EVAL_JOINTS)}
    joints["head"] = {"position_m": None, "pixel": None, "confidence": 0.0}
    joints["neck"].pop("velocity_m_s")  # an older worker's message: no velocity, no motion
    return {"received_ns": received_ns, "bodies": [{"id": 7, "state": "tracking", "joints": joints},
                                                   {"id": 8, "state": "lost", "joints": {}}]}


def test_pose_at_moves_each_joint_by_its_velocity_over_the_time_since_the_frame_was_taken():
    out = pose_at(_message(1_000_000_000), t_ns=1_100_000_000)  # 0.1 s later
    assert set(out) == {7}  # a lost body has no pose
    k = EVAL_JOINTS.index("left_wrist")
    assert out[7]["left_wrist"] == pytest.approx([k + 0.1, -0.05, 2.0])
    assert out[7]["head"] is None
    assert out[7]["neck"] == pytest.approx([float(EVAL_JOINTS.index("neck")), 0.0, 2.0])


def test_the_time_is_capped_at_the_horizon_and_never_runs_backwards():
    joints, velocity = np.zeros((2, 3)), np.ones((2, 3))
    np.testing.assert_allclose(extrapolate(joints, velocity, 5.0), HORIZON_S)
    np.testing.assert_allclose(extrapolate(joints, velocity, -1.0), 0.0)
    np.testing.assert_allclose(extrapolate(joints, np.full((2, 3), np.nan), 0.1), 0.0)
