"""The 36-D pose vector and Table 1 of the paper."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import (
    ANGLE_LIMITS,
    ANGLE_NAMES,
    BLAZEPOSE33,
    BODY25,
    COCO17,
    EVAL_JOINTS,
    POINT_NAMES,
    clamp_pose,
    neutral_pose,
)

# Table 1 as printed (ankle pitch read as -0.6..0.6, see DESIGN.md), in pose-vector order.
TABLE1 = [
    ("neck.roll", -0.4, 0.4), ("neck.pitch", -0.3, 0.3),
    ("spine.roll", -0.5, 0.5), ("spine.pitch", -0.2, 0.5), ("spine.yaw", -1.5, 1.5),
    ("left_collar.roll", -0.1, 0.1), ("left_collar.yaw", -0.15, 0.1),
    ("right_collar.roll", -0.1, 0.1), ("right_collar.yaw", -0.1, 0.15),
    ("left_shoulder.roll", -4, 4), ("left_shoulder.pitch", -1.8, 1.57), ("left_shoulder.yaw", -2, 1.4),
    ("right_shoulder.roll", -4, 4), ("right_shoulder.pitch", -1.8, 1.57), ("right_shoulder.yaw", -1.4, 2),
    ("left_elbow.yaw", -2.5, 0), ("right_elbow.yaw", 0, 2.5),
    ("left_hip.roll", -1.57, 1.57), ("left_hip.pitch", -0.78, 2), ("left_hip.yaw", -1.2, 0.5),
    ("right_hip.roll", -1.57, 1.57), ("right_hip.pitch", -0.78, 2), ("right_hip.yaw", -0.5, 1.2),
    ("left_knee.pitch", -2.8, 0.1), ("right_knee.pitch", -2.8, 0.1),
    ("left_ankle.pitch", -0.6, 0.6), ("left_ankle.yaw", -0.7, 0.7),
    ("right_ankle.pitch", -0.6, 0.6), ("right_ankle.yaw", -0.7, 0.7),
]


def test_angles_follow_table1_exactly():
    assert list(ANGLE_NAMES) == [n for n, _, _ in TABLE1]
    np.testing.assert_array_equal(ANGLE_LIMITS, [[lo, hi] for _, lo, hi in TABLE1])


def test_clamp_pose_enforces_limits_and_renormalises():
    rng = np.random.default_rng(0)
    h = rng.normal(scale=5.0, size=(100, 36))
    c = clamp_pose(h)
    assert np.all(c[:, 7:] >= ANGLE_LIMITS[:, 0]) and np.all(c[:, 7:] <= ANGLE_LIMITS[:, 1])
    np.testing.assert_allclose(np.linalg.norm(c[:, 3:7], axis=1), 1.0)
    np.testing.assert_array_equal(c[:, :3], h[:, :3])
    inside = neutral_pose()
    inside[7:] = ANGLE_LIMITS.mean(axis=1)
    np.testing.assert_array_equal(clamp_pose(inside), inside)


def test_layouts_have_their_published_sizes_and_map_onto_body_points():
    assert (len(COCO17.keypoints), len(BODY25.keypoints), len(BLAZEPOSE33.keypoints)) == (17, 25, 33)
    for layout in (COCO17, BODY25, BLAZEPOSE33):
        assert all(p in POINT_NAMES for p in layout.mapped.values())
    assert BODY25.point_of("left_big_toe") == "left_toe" and BODY25.point_of("left_small_toe") is None
    assert BLAZEPOSE33.point_of("right_foot_index") == "right_toe" and BLAZEPOSE33.point_of("mouth_left") is None
    assert set(EVAL_JOINTS) - {"head", "neck"} <= set(COCO17.mapped.values())
