"""The procedural motions: shapes, limits, smoothness, periodicity and what each one moves."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.kinematics import axis_angle_matrix
from swarmpose.body.skeleton import ANGLE_NAMES, TRACKING_JOINTS
from swarmpose.core.errors import ConfigError
from swarmpose.motion.builtin import (
    ANKLE_OUTSET,
    ARMS_DOWN,
    BUILTIN_MOTIONS,
    PERIODS,
    SHIN_LENGTH,
    THIGH_LENGTH,
    builtin_motion,
    relaxed_stance,
)
from swarmpose.motion.sequence import Motion

FPS = 30.0


def angle(motion: Motion, name: str) -> np.ndarray:
    """The (N,) track of the Table 1 angle ``name``."""
    return motion.angles[:, ANGLE_NAMES.index(name)]


def dof_axis(name: str) -> tuple[float, float, float]:
    joint, kind = name.split(".")
    return next(j for j in TRACKING_JOINTS if j.name == joint).dof(kind).axis


def test_the_required_motions_exist():
    assert {"wave", "squat", "walk", "turn", "jumping_jacks"} <= set(BUILTIN_MOTIONS)


@pytest.mark.parametrize("name", BUILTIN_MOTIONS)
@pytest.mark.parametrize("frames", [1, 7, 150])
def test_shapes_limits_and_rotations(name, frames):
    m = builtin_motion(name, frames, FPS)
    assert isinstance(m, Motion) and m.name == name and m.fps == FPS and len(m) == frames
    assert m.angles.shape == (frames, 29) and m.root_offset.shape == (frames, 3)
    assert m.root_rotation.shape == (frames, 3, 3)
    assert m.within_limits()
    for arr in (m.angles, m.root_offset, m.root_rotation):
        assert np.all(np.isfinite(arr))
    np.testing.assert_allclose(m.root_rotation @ np.swapaxes(m.root_rotation, 1, 2),
                               np.broadcast_to(np.eye(3), (frames, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m.root_rotation), 1.0, atol=1e-12)
    if name != "turn":
        np.testing.assert_array_equal(m.root_rotation, np.broadcast_to(np.eye(3), (frames, 3, 3)))
    if name not in ("squat", "jumping_jacks"):
        np.testing.assert_array_equal(m.root_offset, 0.0)


@pytest.mark.parametrize("name", BUILTIN_MOTIONS)
def test_smooth_at_30_fps(name):
    m = builtin_motion(name, 300, FPS)
    assert np.max(np.abs(np.diff(m.angles, axis=0))) <= 0.3
    assert np.max(np.linalg.norm(np.diff(m.root_offset, axis=0), axis=1)) <= 0.05
    step = np.einsum("nji,njk->nik", m.root_rotation[:-1], m.root_rotation[1:])
    step_angle = np.arccos(np.clip((np.trace(step, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert np.max(step_angle) <= 0.3


@pytest.mark.parametrize("name", sorted(PERIODS))
def test_periodic(name):
    period = int(round(PERIODS[name] * FPS))
    m = builtin_motion(name, 3 * period, FPS)
    np.testing.assert_allclose(m.angles[period:], m.angles[:-period], atol=1e-9)
    np.testing.assert_allclose(m.root_offset[period:], m.root_offset[:-period], atol=1e-9)
    assert np.ptp(m.angles, axis=0).max() > 0.3  # it does move


@pytest.mark.parametrize("name", BUILTIN_MOTIONS)
def test_deterministic(name):
    a, b = builtin_motion(name, 40, 25.0), builtin_motion(name, 40, 25.0)
    for x, y in ((a.angles, b.angles), (a.root_offset, b.root_offset), (a.root_rotation, b.root_rotation)):
        np.testing.assert_array_equal(x, y)


def test_other_frame_rates_sample_the_same_curve():
    slow = builtin_motion("walk", 30, 15.0)
    fast = builtin_motion("walk", 60, 30.0)
    np.testing.assert_allclose(slow.angles, fast.angles[::2], atol=1e-12)


# ---------------------------------------------------------------------------- what each motion does
def test_squat_flexes_and_lowers_with_feet_planted():
    m = builtin_motion("squat", int(PERIODS["squat"] * FPS), FPS)
    for side in ("left", "right"):
        assert angle(m, f"{side}_knee.pitch").min() < -1.0
        assert angle(m, f"{side}_hip.pitch").max() > 0.5
        # Foot flat: the sagittal rotations hip (-X), knee (-X) and ankle (+X) cancel.
        total = angle(m, f"{side}_ankle.pitch") - angle(m, f"{side}_hip.pitch") - angle(m, f"{side}_knee.pitch")
        np.testing.assert_allclose(total, 0.0, atol=1e-12)
    assert m.root_offset[:, 1].min() < -0.1 and m.root_offset[:, 1].max() <= 1e-12
    np.testing.assert_allclose(m.angles[0], relaxed_stance(), atol=1e-12)
    # Independent leg model: thigh and shin of the documented lengths, the ankle
    # ANKLE_OUTSET outside the hip, rotated by the hip (roll, pitch) and knee (pitch) about
    # the skeleton's own DOF axes. The ankle must not move up/down or forward/back.
    for side in ("left", "right"):
        out = ANKLE_OUTSET if side == "left" else -ANKLE_OUTSET
        roll = axis_angle_matrix(dof_axis(f"{side}_hip.roll"), angle(m, f"{side}_hip.roll"))
        hip = roll @ axis_angle_matrix(dof_axis(f"{side}_hip.pitch"), angle(m, f"{side}_hip.pitch"))
        knee = axis_angle_matrix(dof_axis(f"{side}_knee.pitch"), angle(m, f"{side}_knee.pitch"))
        thigh = np.array([out / 2, -THIGH_LENGTH, 0.0])
        shin = np.array([out / 2, -SHIN_LENGTH, 0.0])
        ankle = m.root_offset + hip @ thigh + np.einsum("nij,nj->ni", hip @ knee, np.broadcast_to(shin, (len(m), 3)))
        np.testing.assert_allclose(ankle[:, 1], -(THIGH_LENGTH + SHIN_LENGTH), atol=1e-9)
        np.testing.assert_allclose(ankle[:, 2], 0.0, atol=1e-9)


def test_walk_alternates_legs_and_counter_swings_arms():
    m = builtin_motion("walk", int(2 * PERIODS["walk"] * FPS), FPS)
    left, right = angle(m, "left_hip.pitch"), angle(m, "right_hip.pitch")
    assert left.max() > 0.5 and right.max() > 0.5
    assert np.all(np.minimum(left, right) < 1e-12)  # never both legs lifted
    assert angle(m, "left_knee.pitch").min() < -0.8 and angle(m, "right_knee.pitch").min() < -0.8
    lifted_left = left > 0.3
    # Left leg forward -> right arm forward (right yaw > 0), left arm back (left yaw > 0).
    assert np.all(angle(m, "right_shoulder.yaw")[lifted_left] > 0.1)
    assert np.all(angle(m, "left_shoulder.yaw")[lifted_left] > 0.1)
    lifted_right = right > 0.3
    assert np.all(angle(m, "left_shoulder.yaw")[lifted_right] < -0.1)
    assert 0.02 < np.ptp(angle(m, "spine.yaw")) < 0.4
    np.testing.assert_array_equal(m.root_offset, 0.0)


@pytest.mark.parametrize("frames", [12, 90, 361])
def test_turn_makes_one_revolution(frames):
    m = builtin_motion("turn", frames, FPS)
    forward = m.root_rotation @ np.array([0.0, 0.0, 1.0])
    yaw = np.unwrap(np.arctan2(forward[:, 0], forward[:, 2]))
    assert yaw[0] == pytest.approx(0.0, abs=1e-12)
    assert yaw[-1] == pytest.approx(2 * np.pi * (frames - 1) / frames, abs=1e-9)
    assert np.all(np.diff(yaw) > 0)
    np.testing.assert_allclose(m.root_rotation @ np.array([0.0, 1.0, 0.0]), np.tile([0.0, 1.0, 0.0], (frames, 1)),
                               atol=1e-12)
    np.testing.assert_array_equal(m.angles, np.tile(relaxed_stance(), (len(m), 1)))


def test_wave_raises_the_right_arm_and_waves_the_forearm():
    m = builtin_motion("wave", int(2 * PERIODS["wave"] * FPS), FPS)
    elbow = angle(m, "right_elbow.yaw")
    assert np.ptp(elbow) > 0.3 and elbow.min() > 0.0  # right elbow flexion is positive
    assert np.all(angle(m, "right_shoulder.roll") < -0.3)  # right arm raised above the T-pose
    np.testing.assert_array_equal(angle(m, "left_shoulder.roll"), -ARMS_DOWN)  # left arm hangs
    np.testing.assert_array_equal(m.angles[:, [ANGLE_NAMES.index(n) for n in ANGLE_NAMES if "hip" in n or "knee" in n]],
                                  0.0)


def test_jumping_jacks_arms_over_head_and_legs_apart():
    period = int(PERIODS["jumping_jacks"] * FPS)
    m = builtin_motion("jumping_jacks", period + 1, FPS)
    up = period // 2  # arms-up, legs-apart phase
    assert angle(m, "left_shoulder.roll")[up] > 1.5 and angle(m, "right_shoulder.roll")[up] < -1.5
    assert angle(m, "left_hip.roll")[up] > 0.2 and angle(m, "right_hip.roll")[up] < -0.2
    np.testing.assert_allclose(m.angles[[0, period]], np.tile(relaxed_stance(), (2, 1)), atol=1e-12)  # closed
    assert m.root_offset[:, 1].max() > 0.03  # the hop, between the stances
    assert m.root_offset[period // 4, 1] > 0.0
    np.testing.assert_allclose(m.root_offset[:, [0, 2]], 0.0)


# ---------------------------------------------------------------------------- errors
def test_unknown_motion_names_the_valid_ones():
    with pytest.raises(ConfigError) as info:
        builtin_motion("moonwalk", 10)
    for name in BUILTIN_MOTIONS:
        assert name in str(info.value)


@pytest.mark.parametrize("frames", [0, -3, 2.5, True])
def test_bad_frame_count(frames):
    with pytest.raises(ConfigError, match="frames"):
        builtin_motion("wave", frames)


@pytest.mark.parametrize("fps", [0.0, -30.0, float("nan"), float("inf")])
def test_bad_fps(fps):
    with pytest.raises(ConfigError, match="fps"):
        builtin_motion("wave", 10, fps)


def test_motions_mean_what_they_say_on_a_posed_body():
    """Oracle independent of the generator's angle values: pose the built-in body and look."""
    from swarmpose.body.kinematics import matrix_to_quaternion
    from swarmpose.body.parametric import build_parametric_body

    body = build_parametric_body()

    def points(m, names):
        h = np.zeros((len(m), 36))
        h[:, :3], h[:, 3:7], h[:, 7:] = m.root_offset, matrix_to_quaternion(m.root_rotation), m.angles
        return dict(zip(names, np.moveaxis(body.posed_points(h, names), 1, 0)))

    wave = points(builtin_motion("wave", 30), ["right_wrist", "head", "left_wrist", "left_hip"])
    assert np.all(wave["right_wrist"][:, 1] > wave["head"][:, 1])  # the waving hand is above the head
    assert np.all(wave["left_wrist"][:, 1] < wave["left_hip"][:, 1] + 0.1)  # the other arm hangs
    period = int(PERIODS["jumping_jacks"] * FPS)
    jj = points(builtin_motion("jumping_jacks", period + 1, FPS), ["left_wrist", "right_wrist", "head"])
    up = period // 2
    assert jj["left_wrist"][up, 1] > jj["head"][up, 1] and jj["right_wrist"][up, 1] > jj["head"][up, 1]
    assert jj["left_wrist"][0, 1] < jj["head"][0, 1] - 0.5
    walk = points(builtin_motion("walk", int(PERIODS["walk"] * FPS), FPS), ["left_knee", "left_hip"])
    lift = int(PERIODS["walk"] * FPS) // 4  # sin peak: the left leg lifted
    assert walk["left_knee"][lift, 2] > walk["left_hip"][lift, 2] + 0.15  # the knee swings forward
