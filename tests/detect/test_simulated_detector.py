"""The simulated 2D detector's statistics against its documented noise model."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.skeleton import COCO17
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.simulated import SimulatedNoise, person_size, simulate_detections

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
