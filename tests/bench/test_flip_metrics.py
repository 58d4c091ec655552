"""Flipped frames, swapped sides and the recovery from flips, on hand-made tracks: a standing
skeleton (camera frame, y down, facing the camera), and estimates made from it by turning it
about the vertical through its pelvis, exchanging its left and right labels, or losing it."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.bench.flip_metrics import flip_metrics, flips
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.errors import ShapeError

FPS = 30.0
STANDING = {  # x = the person's left (facing the camera), y down, z away from the camera, m
    "head": (0.0, -0.75, 3.0), "neck": (0.0, -0.55, 3.0),
    "left_shoulder": (0.2, -0.5, 3.0), "right_shoulder": (-0.2, -0.5, 3.0),
    "left_elbow": (0.25, -0.2, 3.05), "right_elbow": (-0.25, -0.2, 2.95),
    "left_wrist": (0.25, 0.05, 2.9), "right_wrist": (-0.3, 0.05, 3.0),
    "left_hip": (0.12, 0.0, 3.0), "right_hip": (-0.12, 0.0, 3.0),
    "left_knee": (0.13, 0.45, 2.95), "right_knee": (-0.13, 0.45, 3.05),
    "left_ankle": (0.13, 0.9, 3.0), "right_ankle": (-0.13, 0.9, 3.1),
}
MIRROR = [EVAL_JOINTS.index(n.replace("left", "@").replace("right", "left").replace("@", "right"))
          for n in EVAL_JOINTS]
"""Index of each joint's other-side twin (itself for head and neck)."""


def track(frames: int = 12) -> np.ndarray:
    """(F, J, 3) the standing skeleton stepping 2 cm a frame to its left."""
    one = np.array([STANDING[n] for n in EVAL_JOINTS])
    return np.stack([one + [0.02 * k, 0.0, 0.0] for k in range(frames)])


def turned(joints: np.ndarray, degrees: float) -> np.ndarray:
    """(J, 3) joints turned about the vertical through the middle of their hips."""
    centre = (joints[EVAL_JOINTS.index("left_hip")] + joints[EVAL_JOINTS.index("right_hip")]) / 2
    a = np.radians(degrees)
    rot = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    return (joints - centre) @ rot.T + centre


def times(frames: int = 12) -> np.ndarray:
    return np.arange(frames) / FPS


def test_a_perfect_track_has_no_flip():
    truth = track()
    out = flip_metrics(truth.copy(), truth, times())
    assert out == {"flipped": 0, "sides_swapped": 0, "flips": 0, "recovery_mean_s": None,
                   "recovery_max_s": None, "unrecovered": 0}


def test_a_torso_turned_round_for_five_frames_is_five_flipped_frames_and_five_periods_to_recover():
    truth = track()
    est = truth.copy()
    for k in range(3, 8):
        est[k] = turned(truth[k], 180.0)
    out = flip_metrics(est, truth, times())
    assert out["flipped"] == 5 and out["sides_swapped"] == 5, "turned round: faces away, its left where the right is"
    assert out["flips"] == 1 and out["unrecovered"] == 0
    assert out["recovery_mean_s"] == pytest.approx(5 / FPS) and out["recovery_max_s"] == pytest.approx(5 / FPS)


def test_a_flip_at_90_degrees_is_the_threshold():
    truth = track(2)
    est = truth.copy()
    est[0] = turned(truth[0], 80.0)
    est[1] = turned(truth[1], -100.0)
    out = flip_metrics(est, truth, times(2))
    assert out["flipped"] == 1 and out["sides_swapped"] == 1, "80° is neither, 100° both"
    assert out["unrecovered"] == 1 and out["recovery_max_s"] == pytest.approx(1 / FPS)


def test_swapped_labels_count_as_swapped_sides_and_their_flips_recover():
    truth = track()
    est = truth.copy()
    for k in (2, 3, 8):
        est[k] = truth[k][MIRROR]  # the left joints labelled right and the right left
    out = flip_metrics(est, truth, times())
    assert out["sides_swapped"] == 3
    assert out["flipped"] == 3, "left x up reverses with the labels: the facing turns round too"
    assert out["flips"] == 2
    assert out["recovery_mean_s"] == pytest.approx(1.5 / FPS) and out["recovery_max_s"] == pytest.approx(2 / FPS)


def test_swapped_shoulders_alone_are_judged_on_the_torso_pairs_summed():
    truth = track(1)
    est = truth.copy()
    ls, rs = EVAL_JOINTS.index("left_shoulder"), EVAL_JOINTS.index("right_shoulder")
    est[0, [ls, rs]] = truth[0, [rs, ls]]
    out = flip_metrics(est, truth, times(1))
    assert out["sides_swapped"] == 1, "shoulders 0.4 m apart swapped outweigh hips 0.24 m apart kept"
    limbs = truth.copy()
    lw, rw = EVAL_JOINTS.index("left_wrist"), EVAL_JOINTS.index("right_wrist")
    limbs[0, [lw, rw]] = truth[0, [rw, lw]]
    assert flip_metrics(limbs, truth, times(1))["sides_swapped"] == 0, "the wrists are not torso joints"


def test_a_flip_still_on_at_the_end_counts_to_the_end():
    truth = track()
    est = truth.copy()
    for k in range(9, 12):
        est[k] = turned(truth[k], 170.0)
    out = flip_metrics(est, truth, times())
    assert out["flipped"] == 3 and out["flips"] == 1 and out["unrecovered"] == 1
    assert out["recovery_max_s"] == pytest.approx(3 / FPS), "frames 9, 10, 11: to the end of frame 11"


def test_lost_frames_within_a_flip_wait_for_the_next_right_frame_and_alone_are_no_flip():
    truth = track()
    est = truth.copy()
    est[3] = turned(truth[3], 180.0)
    est[4] = turned(truth[4], 180.0)
    est[5] = np.nan  # lost while flipped
    est[9] = np.nan  # lost on its own
    out = flip_metrics(est, truth, times())
    assert out["flipped"] == 2 and out["flips"] == 1
    assert out["recovery_mean_s"] == pytest.approx(3 / FPS), "from frame 3 to the right frame 6"
    assert flips(np.array([False, True, False]), np.array([True, False, True])) == [], \
        "a wrong verdict on a lost frame starts no flip"


def test_the_frame_times_set_the_recovery():
    truth = track(4)
    est = truth.copy()
    est[1] = turned(truth[1], 180.0)
    stamps = np.array([0.0, 0.1, 0.35, 0.4])  # a frame dropped between 1 and 2
    assert flip_metrics(est, truth, stamps)["recovery_max_s"] == pytest.approx(0.25)


def test_bad_shapes_name_the_input():
    truth = track(3)
    with pytest.raises(ShapeError, match="frame times"):
        flip_metrics(truth, truth, times(4))
    with pytest.raises(ShapeError, match="estimated joints"):
        flip_metrics(truth[:2], truth, times(3))
