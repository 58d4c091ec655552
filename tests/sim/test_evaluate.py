"""Δ and A(t) by hand; the plot is a readable PNG."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.sim.evaluate import accuracy, joint_errors, plot_accuracy, summarise


def test_errors_and_summary_by_hand():
    truth = np.zeros((2, 3, 3))
    est = truth.copy()
    est[0, 0] = [0.03, 0.04, 0.0]   # 50 mm
    est[0, 1] = [0.0, 0.0, 0.25]    # 250 mm
    est[1, 2] = np.nan              # no estimate
    err = joint_errors(est, truth)
    assert err[0, 0] == pytest.approx(50.0) and err[0, 1] == pytest.approx(250.0) and np.isnan(err[1, 2])
    s = summarise(err)
    assert s["mpjpe_mm"] == pytest.approx((50 + 250) / 5)
    assert s["coverage"] == pytest.approx(5 / 6)
    assert s["A"][20] == pytest.approx(3 / 6)   # the three zeros; the missing joint is a miss
    assert s["A"][60] == pytest.approx(4 / 6)
    assert s["A"][200] == pytest.approx(4 / 6)
    assert s["per_joint_mm"] == [pytest.approx(25.0), pytest.approx(125.0), pytest.approx(0.0)]
    assert accuracy(np.zeros((0, 14))) == {t: 0.0 for t in range(20, 201, 20)}
    assert summarise(np.full((2, 2), np.nan))["mpjpe_mm"] is None


def test_plot_writes_a_png(tmp_path):
    import cv2

    path = tmp_path / "a.png"
    plot_accuracy({"hybrid": {20: 0.2, 40: 0.6, 60: 0.9}, "joints": {20: 0.1, 40: 0.4, 60: 0.7}}, path, "t")
    img = cv2.imread(str(path))
    assert img is not None and img.shape[0] > 200 and img.shape[1] > 300


def test_torso_facing_by_hand():
    """A torso in the camera frame (y down): left shoulder/hip at +x, up is -y, so forward = left x up
    = (1, 0, 0) x (0, -1, 0) = (0, 0, -1), towards the camera."""
    from swarmpose.body.skeleton import EVAL_JOINTS
    from swarmpose.sim.evaluate import facing_errors_deg, torso_facing

    joints = np.zeros((1, len(EVAL_JOINTS), 3))
    place = {"left_shoulder": (0.2, -0.5, 3.0), "right_shoulder": (-0.2, -0.5, 3.0),
             "left_hip": (0.1, 0.0, 3.0), "right_hip": (-0.1, 0.0, 3.0)}
    for name, p in place.items():
        joints[0, EVAL_JOINTS.index(name)] = p
    assert np.allclose(torso_facing(joints)[0], (0.0, 0.0, -1.0))
    mirrored = joints.copy()
    mirrored[..., 0] *= -1  # left and right exchange sides: the torso faces away
    assert facing_errors_deg(mirrored, joints)[0] == pytest.approx(180.0)
    turned = joints.copy()
    turned[..., [0, 2]] = np.stack([3.0 - joints[..., 2], joints[..., 0]], axis=-1)  # 90° about the vertical
    assert facing_errors_deg(turned, joints)[0] == pytest.approx(90.0)
    missing = joints.copy()
    missing[0, EVAL_JOINTS.index("left_hip")] = np.nan
    assert np.isnan(facing_errors_deg(missing, joints)[0])
