"""Depth flips of the limbs: the same image, the other depth, checked by hand and by projection."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.limb_flips import FLIP_LIMBS, flip_targets, limb_flips, ray_points, solve_limbs
from tests.tracking.one_frame import detection_of, room_depth, step_from

INTR = Intrinsics(width=320, height=240, fx=285.0, fy=285.0, cx=160.0, cy=120.0)
FACING = (0.0, 1.0, 0.0, 0.0)
"""The root quaternion of a body facing the camera (its front towards -z)."""


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


def test_ray_points_by_hand():
    # the optical axis meets the sphere of radius 0.3 around (0, 0, 2.3) at z = 2.0 and 2.6
    near, far = ray_points(np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 2.3]), 0.3)
    assert np.allclose(near, [0.0, 0.0, 2.0]) and np.allclose(far, [0.0, 0.0, 2.6])
    # a ray that passes 0.5 m from the centre misses a 0.3 m sphere: its nearest point
    (nearest,) = ray_points(np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.0, 2.0]), 0.3)
    assert np.allclose(nearest, [0.0, 0.0, 2.0])


def test_an_arm_pointing_at_the_camera_flips_to_point_away():
    # shoulder on the optical axis, upper arm and forearm straight towards the camera
    shoulder, elbow, wrist = np.array([0, 0, 3.0]), np.array([0, 0, 2.7]), np.array([0, 0, 2.45])
    flips = [tuple(np.round(p, 6) for p in pair) for pair in flip_targets(shoulder, elbow, wrist)]
    as_lists = [(m.tolist(), e.tolist()) for m, e in flips]
    # the upper arm mirrored behind the shoulder, the forearm folded back along it or pointing on
    assert ([0, 0, 3.3], [0, 0, 3.05]) in as_lists
    assert ([0, 0, 3.3], [0, 0, 3.55]) in as_lists
    # the forearm alone folded back over the upper arm
    assert ([0, 0, 2.7], [0, 0, 2.95]) in as_lists
    assert len(as_lists) == 3


def test_a_limb_across_the_line_of_sight_has_no_flip():
    # an arm held out sideways, all three points at the same depth on the optical axis's plane
    shoulder, elbow, wrist = np.array([0, 0, 3.0]), np.array([0.3, 0, 3.0]), np.array([0.55, 0, 3.0])
    assert flip_targets(shoulder, elbow, wrist) == []
    # tilted 10 degrees out of that plane (less than MIN_TILT_RAD): still none
    d = np.array([np.cos(np.radians(10)), 0.0, -np.sin(np.radians(10))])
    assert flip_targets(shoulder, shoulder + 0.3 * d, shoulder + 0.55 * d) == []


def test_flips_of_a_tilted_arm_keep_its_bones_and_its_rays():
    d = np.array([np.cos(np.radians(30)), 0.0, -np.sin(np.radians(30))])
    shoulder = np.array([0.1, -0.2, 3.0])
    elbow, wrist = shoulder + 0.3 * d, shoulder + 0.55 * d
    flips = flip_targets(shoulder, elbow, wrist)
    assert flips
    for middle, end in flips:
        assert np.isclose(np.linalg.norm(middle - shoulder), 0.3)
        # the forearm's length, or a little more where the wrist's ray just misses its sphere (its nearest point)
        assert 0.25 - 1e-9 <= np.linalg.norm(end - middle) < 0.26
        assert np.allclose(np.cross(middle, elbow), 0.0, atol=1e-9)  # on the elbow's camera ray
        assert np.allclose(np.cross(end, wrist), 0.0, atol=1e-9)  # on the wrist's camera ray
        assert max(np.linalg.norm(middle - elbow), np.linalg.norm(end - wrist)) > 0.05


def solved_pose(body, start: np.ndarray, limb: int, middle: np.ndarray, end: np.ndarray) -> np.ndarray:
    out, miss = solve_limbs(body, start, [FLIP_LIMBS[limb]], np.array([[middle, end]]))
    assert miss[0] < 0.01, "the solver reaches a reachable arm pose"
    return out[0]


def test_limb_flips_keep_every_joint_in_the_image_and_move_the_arm_in_depth(body):
    rest = body.rest_pose((0.0, 0.0, 3.0), FACING)
    names = ("left_shoulder", "left_elbow", "left_wrist")
    s, e0, w0 = body.posed_points(rest[None], names)[0]
    upper, lower = np.linalg.norm(e0 - s), np.linalg.norm(w0 - e0)
    # the left arm reaching towards the camera, down and in front of the body (squat, push)
    direction = np.array([0.0, 0.45, -1.0]) / np.linalg.norm([0.0, 0.45, -1.0])
    pose = solved_pose(body, rest, 0, s + upper * direction, s + (upper + lower) * direction)

    flips = limb_flips(body, pose)
    assert flips, "an arm along the line of sight has a depth flip"
    points = tuple(n for limb in FLIP_LIMBS for n in limb)
    before = body.posed_points(pose[None], points)[0]
    image = INTR.project(before)
    after = body.posed_points(np.stack(flips), points)
    for flipped in after:
        assert np.abs(INTR.project(flipped) - image).max() < 1.0  # every joint stays on its pixel
    # one flip puts the arm behind the shoulder: the elbow farther than the shoulder by about the
    # upper arm's depth extent towards the camera (the mirror through the plane across the ray)
    elbow_depths = after[:, points.index("left_elbow"), 2]
    behind = before[points.index("left_shoulder"), 2] + (before[points.index("left_shoulder"), 2]
                                                         - before[points.index("left_elbow"), 2])
    assert np.min(np.abs(elbow_depths - behind)) < 0.03
    # the other limbs hang across the line of sight and stay put
    untouched = [points.index(n) for n in points if not n.startswith("left_") or n == "left_shoulder"
                 or "hip" in n or "knee" in n or "ankle" in n]
    assert np.allclose(after[:, untouched], before[untouched], atol=1e-9)


def test_the_rest_pose_facing_the_camera_has_no_flip_its_joints_allow(body):
    """The arms hang across the line of sight: no flip is tried. The shins, below the camera, lean
    out of the plane across their rays by more than MIN_TILT_RAD, but their mirror would bend the
    knees forwards, beyond their limit: tried, missed by more than MAX_MISS_M, dropped."""
    rest = body.rest_pose((0.0, 0.0, 3.0), FACING)
    names = tuple(n for limb in FLIP_LIMBS for n in limb)
    at = dict(zip(names, body.posed_points(rest[None], names)[0]))
    tried = {limb[0]: flip_targets(*(at[n] for n in limb)) for limb in FLIP_LIMBS}
    assert tried["left_shoulder"] == [] and tried["right_shoulder"] == []
    assert tried["left_hip"] and tried["right_hip"], "the shins below the camera are tried"
    assert limb_flips(body, rest) == []


def reaching_pose(body, distance_m: float = 2.5) -> np.ndarray:
    """The body facing the camera with its left arm reaching towards it, down in front of the chest."""
    rest = body.rest_pose((0.0, 0.0, distance_m), FACING)
    s, e, w = body.posed_points(rest[None], ("left_shoulder", "left_elbow", "left_wrist"))[0]
    upper, lower = np.linalg.norm(e - s), np.linalg.norm(w - e)
    direction = np.array([-0.25, 0.45, -1.0]) / np.linalg.norm([-0.25, 0.45, -1.0])
    return solved_pose(body, rest, 0, s + upper * direction, s + (upper + lower) * direction)


@pytest.mark.parametrize("flips", [True, False])
def test_a_track_with_the_arm_behind_the_body_finds_it_in_front_again(body, flips):
    """One frame: the true arm reaches towards the camera; the track starts from its depth mirror
    (the same image, the arm behind the shoulder). With the flips the search lands on the true arm
    (oracle: the render's own joints; 6 mm when written); without them the per-frame search
    (±0.25 rad around the track, the image not having moved) cannot reach it (0.62 m when written:
    a control that shows the flips are what finds the arm; the arm proposals, which find it too,
    are off in both)."""
    intr = Intrinsics.kinect_v1()
    lod = body.tracking_lod(1500)
    truth = reaching_pose(lod)
    names = ("left_elbow", "left_wrist")
    true_arm = lod.posed_points(truth[None], names)[0]
    behind = [p for p in limb_flips(lod, truth)
              if lod.posed_points(p[None], ("left_elbow",))[0, 0, 2] > true_arm[0, 2] + 0.2]
    assert behind, "the reaching arm has a mirror behind the shoulder"
    wrong = behind[0]
    config = TrackerConfig(particles=32, generations=32, recheck=0, limb_flips=flips, arm_proposals=False)
    pose = step_from(lod, intr, wrong, room_depth(lod, truth, intr), detection_of(lod, truth, intr), config)
    found = lod.posed_points(pose[None], names)[0]
    miss_m = np.linalg.norm(found - true_arm, axis=1).max()
    if flips:
        assert miss_m < 0.05
    else:
        assert miss_m > 0.15
