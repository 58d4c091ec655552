"""Joint velocities of the published bodies against hand computation, and the message that carries them."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.messages import validate
from swarmpose.pipeline.velocity import BLEND, JointVelocities
from swarmpose.tracking.result import BodyResult, FrameResult, lost_body

J = len(EVAL_JOINTS)


def _body(joints: np.ndarray, body_id: int = 0) -> BodyResult:
    return BodyResult(body_id, "tracking", "", None, joints, np.zeros((J, 2)), np.ones(J))


def _frame(index: int, t_s: float, *bodies: BodyResult) -> FrameResult:
    return FrameResult(index, int(round(t_s * 1e9)), tuple(bodies))


def test_the_first_frame_has_zero_velocity_the_next_the_difference_then_a_blend():
    a = np.zeros((J, 3))
    v = JointVelocities()
    first = v(_frame(0, 1.0, _body(a)))
    assert np.array_equal(first.bodies[0].velocities, np.zeros((J, 3)))
    second = v(_frame(3, 1.1, _body(a + [0.1, 0.0, 0.0])))  # 0.1 m in x, 0.1 s later (two frames dropped)
    np.testing.assert_allclose(second.bodies[0].velocities, np.tile([1.0, 0.0, 0.0], (J, 1)))  # 1 m/s
    third = v(_frame(6, 1.2, _body(a + [0.1, 0.2, 0.0])))  # then 0.2 m in y in 0.1 s: 2 m/s in y
    np.testing.assert_allclose(third.bodies[0].velocities, np.tile([1 - BLEND, 2 * BLEND, 0.0], (J, 1)))


def test_each_id_has_its_own_and_a_lost_body_or_a_long_gap_starts_over():
    a = np.zeros((J, 3))
    v = JointVelocities()
    v(_frame(0, 0.0, _body(a, 1), _body(a, 2)))
    out = v(_frame(1, 0.1, _body(a + 0.1, 1), lost_body("gone", 2)))
    np.testing.assert_allclose(out.bodies[0].velocities, 1.0)  # 0.1 m in 0.1 s
    assert out.bodies[1].velocities is None
    back = v(_frame(2, 0.2, _body(a + 0.5, 1), _body(a, 2)))
    assert np.all(back.bodies[1].velocities == 0)  # body 2 starts over after being lost
    late = v(_frame(60, 2.3, _body(a, 1)))  # 2.1 s after: more than MAX_GAP_S
    assert np.all(late.bodies[0].velocities == 0)


def test_the_message_carries_the_velocities_turned_into_the_world_frame():
    joints = np.arange(J * 3, dtype=float).reshape(J, 3) / 10
    velocity = np.tile([1.0, 2.0, 3.0], (J, 1))
    velocity[4] = np.nan  # no velocity for this joint
    body = BodyResult(0, "tracking", "", None, joints, np.zeros((J, 2)), np.ones(J), velocities=velocity)
    turn = np.eye(4)
    turn[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 degrees about z
    turn[:3, 3] = [5.0, 6.0, 7.0]  # a translation moves positions, not velocities
    message = body.to_message(turn)
    names = list(EVAL_JOINTS)  # the velocities' order; the message holds more joints, without velocities
    assert message["joints"][names[0]]["velocity_m_s"] == [-2.0, 1.0, 3.0]
    assert "velocity_m_s" not in message["joints"][names[4]]
    frame = FrameResult(0, 0, (body,)).to_message("cam", received_ns=1, publish_ns=2)
    validate(frame)
    assert all("velocity_m_s" not in joint for name, joint in message["joints"].items() if name not in EVAL_JOINTS)
