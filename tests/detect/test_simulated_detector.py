"""The simulated 2D detector's statistics against its documented noise model, and its choice of
person in a multi-person sequence against hand-made ground truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from swarmpose.body.skeleton import COCO17, EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import DetectorError
from swarmpose.detect.simulated import (
    SimulatedDetector,
    SimulatedNoise,
    box_iou,
    match_person,
    person_size,
    simulate_detections,
)
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import GroundTruth, PersonTruth

INTR = Intrinsics.kinect_v1()
SIZE = 300.0
# A standing person around the image centre, 300 px tall.
TRUTH = {
    "nose": (320, 100), "left_eye": (326, 95), "right_eye": (314, 95), "left_ear": (334, 98), "right_ear": (306, 98),
    "neck": (320, 125), "left_shoulder": (350, 135), "right_shoulder": (290, 135), "left_elbow": (365, 190),
    "right_elbow": (275, 190), "left_wrist": (370, 240), "right_wrist": (270, 240), "mid_hip": (320, 245),
    "left_hip": (337, 245), "right_hip": (303, 245), "left_knee": (340, 320), "right_knee": (300, 320),
    "left_ankle": (342, 395), "right_ankle": (298, 395),
}
POINTS = {k: np.asarray(v, dtype=np.float64) for k, v in TRUTH.items()}
OK = dict.fromkeys(POINTS, True)
NONE = SimulatedNoise(jitter=0.0, hip_bias=0.0, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0)


def _run(noise: SimulatedNoise, frames: int, seed: int = 0) -> np.ndarray:
    """(frames, 17, 3) detections."""
    out = [simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, seed, f) for f in range(frames)]
    return np.array([[d[k] for k in COCO17.keypoints] for d in out])


def _truth() -> np.ndarray:
    return np.array([POINTS[k] for k in COCO17.keypoints])


def test_without_noise_detections_are_the_truth():
    det = _run(NONE, 20)
    np.testing.assert_allclose(det[..., :2], np.broadcast_to(_truth(), (20, 17, 2)))
    assert np.all((det[..., 2] >= 0.6) & (det[..., 2] <= 1.0))


def test_jitter_std_is_the_documented_fraction_of_person_size():
    det = _run(SimulatedNoise(jitter=0.01, hip_bias=0.0, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0), 3000)
    err = det[..., :2] - _truth()
    assert np.std(err) == pytest.approx(0.01 * SIZE, rel=0.03)
    assert abs(np.mean(err)) < 0.1


def test_missing_and_outlier_rates():
    noise = SimulatedNoise(jitter=0.0, hip_bias=0.0, outlier_rate=0.05, swap_rate=0.0, missing_rate=0.04)
    det = _run(noise, 4000)
    assert np.mean(det[..., 2] == 0) == pytest.approx(0.04, abs=0.005)
    err = np.linalg.norm(det[..., :2] - _truth(), axis=-1)
    present = det[..., 2] > 0
    outlier = present & (det[..., 2] < 0.6)
    assert outlier.sum() / present.sum() == pytest.approx(0.05, abs=0.006)
    assert np.all(err[outlier] <= np.sqrt(2) * 0.15 * SIZE + 1e-9)
    assert np.all(err[present & ~outlier] < 1e-9)


def test_swap_rate():
    noise = SimulatedNoise(jitter=0.0, hip_bias=0.0, outlier_rate=0.0, swap_rate=0.1, missing_rate=0.0)
    det = _run(noise, 4000)
    left = [COCO17.keypoints.index(k) for k in COCO17.keypoints if k.startswith("left_")]
    right = [COCO17.keypoints.index("right_" + COCO17.keypoints[i][5:]) for i in left]
    swapped_frames = np.any(np.all(np.isclose(det[:, left, :2], _truth()[right]), axis=-1), axis=1)
    assert np.mean(swapped_frames) == pytest.approx(0.1, abs=0.02)


def test_hip_bias_moves_hips_towards_the_neck():
    det = _run(SimulatedNoise(jitter=0.0, hip_bias=0.03, outlier_rate=0.0, swap_rate=0.0, missing_rate=0.0), 3)
    i = COCO17.keypoints.index("left_hip")
    moved = det[0, i, :2] - POINTS["left_hip"]
    toward = (POINTS["neck"] - POINTS["left_hip"]) / np.linalg.norm(POINTS["neck"] - POINTS["left_hip"])
    np.testing.assert_allclose(moved, 0.03 * SIZE * toward, atol=1e-9)
    np.testing.assert_allclose(det[0, COCO17.keypoints.index("left_knee"), :2], POINTS["left_knee"])


def test_points_outside_the_image_or_behind_the_camera_are_missing():
    pts = dict(POINTS)
    pts["left_wrist"] = np.array([700.0, 240.0])
    behind = dict(OK, right_wrist=False)
    det = simulate_detections(COCO17, pts, behind, SIZE, INTR, NONE, 0, 0)
    assert det["left_wrist"] == [0.0, 0.0, 0.0] and det["right_wrist"] == [0.0, 0.0, 0.0]
    assert det["nose"][2] > 0


def test_same_seed_and_frame_same_output():
    noise = SimulatedNoise()
    a = simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17)
    b = simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17)
    c = simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 6, 17)
    assert a == b and a != c


def test_person_size_is_the_larger_side_of_the_box():
    assert person_size(np.array([[0, 0], [30, 100], [np.nan, 5]])) == 100.0


def test_each_person_of_a_scene_draws_its_own_noise_and_person_one_the_single_person_draws():
    noise = SimulatedNoise()
    legacy = simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17)
    assert simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17, stream=0) == legacy
    second = simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17, stream=1)
    assert second != legacy and second == simulate_detections(COCO17, POINTS, OK, SIZE, INTR, noise, 5, 17, stream=1)


def test_hidden_points_are_missing():
    hidden = dict(OK, left_shoulder=False, left_wrist=False)
    det = simulate_detections(COCO17, POINTS, hidden, SIZE, INTR, NONE, 0, 3)
    assert det["left_shoulder"] == det["left_wrist"] == [0.0, 0.0, 0.0]
    assert all(det[k][2] > 0 for k in COCO17.keypoints if k not in ("left_shoulder", "left_wrist"))


# Two people by hand: person 1 in front spans x 105..195 px; person 2 stands behind it, its
# joints inside person 1's box, only a strip x 150..190 of it visible, its last 3 joints hidden.
J = len(EVAL_JOINTS)


def _person(pid: int, xs: tuple[float, float], box, hidden: int = 0, visible: float = 1.0) -> PersonTruth:
    xy = np.c_[np.linspace(*xs, J), np.linspace(70, 370, J)]
    keypoints = np.c_[xy[np.arange(len(COCO17.keypoints)) % J] + pid, np.full(len(COCO17.keypoints), 0.9)]
    occluded = np.zeros(J, bool)
    occluded[J - hidden:] = hidden > 0
    return PersonTruth(pid, np.zeros(36), np.c_[np.zeros((J, 2)), np.full(J, 3.0)], xy, ("coco17", keypoints),
                       visible, None if box is None else np.asarray(box, float), occluded)


def _scene_truth(*people: PersonTruth) -> GroundTruth:
    return GroundTruth((7,), np.zeros((1, 36)), people[0].joints3d[None], (people[0].detection,),
                       people=(tuple(people),))


def _frame() -> Frame:
    return Frame(7, 0, np.zeros((480, 640), np.float32), None, INTR)


FRONT = _person(1, (105, 195), [100, 50, 200, 400])
BACK = _person(2, (155, 185), [150, 60, 190, 380], hidden=3, visible=0.3)


def test_a_box_picks_the_person_whose_visible_joints_it_holds():
    detector = SimulatedDetector(_scene_truth(FRONT, BACK), "two people")
    # Around person 1: both people's visible joints are all inside; the IoU with person 1's box decides.
    assert np.array_equal(detector.detect(_frame(), np.array([100.0, 50, 200, 400])).keypoints, FRONT.detection[1])
    # Around person 2's visible strip: all of its visible joints, a minority of person 1's.
    assert np.array_equal(detector.detect(_frame(), np.array([150.0, 60, 190, 300])).keypoints, BACK.detection[1])
    # No box: person 1; a box around nobody: every keypoint missing.
    assert np.array_equal(detector.detect(_frame()).keypoints, FRONT.detection[1])
    assert not detector.detect(_frame(), np.array([400.0, 10, 500, 100])).keypoints.any()


def test_match_person_ignores_hidden_joints_and_joints_outside_the_image():
    # Person 2's hidden joints (the lowest three) lie outside this box; its other joints all inside.
    box = np.array([150.0, 60, 190, 300])
    assert match_person((FRONT, BACK), box, INTR) == 1
    unhidden = _person(2, (155, 185), [150, 60, 190, 380])
    assert match_person((FRONT, unhidden), box, INTR) == 1  # still the larger share: 10/13 against 4/13
    # Person 1 with every joint hidden but the four in the box: 4/4 against 10/13.
    front_hidden = replace(FRONT, occluded=~np.isin(np.arange(J), [6, 7, 8, 9]))
    assert match_person((front_hidden, unhidden), box, INTR) == 0
    offscreen = _person(3, (-200, -100), [0, 60, 5, 380])
    assert match_person((offscreen,), np.array([0.0, 0, 639, 479]), INTR) == 0  # by IoU: no joint is seen
    assert box_iou(np.array([0.0, 0, 9, 9]), np.array([5.0, 0, 14, 9])) == pytest.approx(50 / 150)


def test_detect_people_lists_the_visible_people_with_their_ids():
    hidden_all = _person(3, (300, 320), None, visible=0.0)
    detector = SimulatedDetector(_scene_truth(FRONT, BACK, hidden_all), "three people")
    got = detector.detect_people(_frame())
    assert [i for i, _ in got] == [1, 2]
    assert np.array_equal(got[1][1].keypoints, BACK.detection[1])


def test_a_malformed_box_is_refused():
    detector = SimulatedDetector(_scene_truth(FRONT, BACK), "two people")
    for box in ([1, 2, 3], [10, 10, 5, 20], [0, 0, np.nan, 5]):
        with pytest.raises(DetectorError, match=r"box must be \[x0, y0, x1, y1\]"):
            detector.detect(_frame(), np.asarray(box, float))
