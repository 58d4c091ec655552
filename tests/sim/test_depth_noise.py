"""The Kinect-like depth noise model against the statistics its documentation states."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.sim.depth_noise import KinectNoise

CLEAN = KinectNoise(quantise=False, edge_dropout=0.0, random_dropout=0.0)


@pytest.mark.parametrize("z", [1.0, 2.0, 3.0, 4.0])
def test_axial_noise_std_matches_documented_formula(z):
    depth = np.full((300, 300), z)
    noisy = CLEAN.apply(depth, np.random.default_rng(1)).astype(np.float64)
    expected = 0.0012 + 0.0019 * (z - 0.4) ** 2  # Nguyen et al. 2012, as documented
    assert np.std(noisy - z) == pytest.approx(expected, rel=0.03)
    assert abs(np.mean(noisy - z)) < 4 * expected / 300


def test_quantisation_puts_depth_on_the_disparity_grid():
    model = KinectNoise(axial_a=0.0, axial_b=0.0, edge_dropout=0.0, random_dropout=0.0)
    z = np.linspace(0.8, 4.0, 4000).reshape(40, 100)
    out = model.apply(z, np.random.default_rng(0)).astype(np.float64)
    fb = 580.0 * 0.075 * 8
    disparity = fb / out
    np.testing.assert_allclose(disparity, np.round(disparity), atol=2e-3)  # float32 output
    assert np.max(np.abs(out - z)) <= 0.5 * model.step(4.0) * 1.05
    levels = np.unique(np.round(out[np.abs(out - 3.0) < 0.1], 5))
    assert np.median(np.diff(levels)) == pytest.approx(model.step(3.0), rel=0.05)  # 3^2/348 = 2.6 cm


def test_edge_pixels_drop_at_the_documented_rate_and_only_there():
    model = KinectNoise(axial_a=0.0, axial_b=0.0, quantise=False, random_dropout=0.0, edge_dropout=0.6)
    depth = np.full((400, 400), 2.0)
    depth[:, 200:] = 3.0  # a 1 m step: columns 199 and 200 are edge pixels
    out = model.apply(depth, np.random.default_rng(3))
    edge = out[:, 199:201]
    assert np.mean(edge == 0) == pytest.approx(0.6, abs=0.05)
    assert np.all(out[:, :198] > 0) and np.all(out[:, 202:] > 0)


def test_random_dropout_rate_and_range_limits():
    model = KinectNoise(axial_a=0.0, axial_b=0.0, quantise=False, edge_dropout=0.0, random_dropout=0.05)
    out = model.apply(np.full((500, 500), 2.0), np.random.default_rng(4))
    assert np.mean(out == 0) == pytest.approx(0.05, abs=0.005)
    far = np.full((10, 10), 9.0)
    near = np.full((10, 10), 0.2)
    assert np.all(CLEAN.apply(far, np.random.default_rng(0)) == 0)
    assert np.all(CLEAN.apply(near, np.random.default_rng(0)) == 0)
    holes = np.zeros((10, 10))
    assert np.all(KinectNoise().apply(holes, np.random.default_rng(0)) == 0)


def test_same_seed_same_noise():
    depth = np.random.default_rng(9).uniform(1, 4, (64, 64))
    a = KinectNoise().apply(depth, np.random.default_rng(7))
    b = KinectNoise().apply(depth, np.random.default_rng(7))
    c = KinectNoise().apply(depth, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
