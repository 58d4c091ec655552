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
