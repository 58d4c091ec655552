"""The One-Euro filter against hand computation, and the tracker publishing filtered poses
while its search stays unfiltered."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_tracker import SMALL, frames_of

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS, ROOT_QUATERNION
from swarmpose.core.camera import Intrinsics
from swarmpose.motion.builtin import builtin_motion
from swarmpose.sim.synth import SynthConfig, synthesize
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.one_euro import OneEuroFilter, PoseFilter


def test_the_first_sample_passes_and_a_constant_stays():
    f = OneEuroFilter(1.0, 0.5)
    x = np.array([1.0, -2.0, 3.5])
    assert np.array_equal(f(x, 0.0), x)
    for k in range(1, 20):
        assert np.allclose(f(x, k / 30), x)


def test_with_beta_zero_it_is_the_exponential_filter_of_its_cutoff():
    """beta = 0: x_f(k) = x_f(k-1) + a (x(k) - x_f(k-1)), a = 1 / (1 + 1 / (2 pi f dt)), by hand."""
    f, dt, cutoff = OneEuroFilter(2.0, 0.0), 0.05, 2.0
    a = 1.0 / (1.0 + 1.0 / (2 * math.pi * cutoff * dt))
    rng = np.random.default_rng(1)
    xs = rng.normal(size=(30, 4))
    expected = xs[0].copy()
    assert np.allclose(f(xs[0], 0.0), expected)
    for k in range(1, 30):
        expected = expected + a * (xs[k] - expected)
        assert np.allclose(f(xs[k], k * dt), expected)


def test_the_cutoff_rises_with_speed_by_beta():
    """Second sample of a ramp: the speed estimate is a_d * v, the cut-off min + beta * a_d * v (by hand)."""
    dt, v, beta, fmin = 1 / 30, 3.0, 0.8, 1.0
    f = OneEuroFilter(fmin, beta, d_cutoff_hz=1.0)
    f(np.zeros(1), 0.0)
    a_d = 1.0 / (1.0 + 1.0 / (2 * math.pi * 1.0 * dt))
    cutoff = fmin + beta * a_d * v
    a = 1.0 / (1.0 + 1.0 / (2 * math.pi * cutoff * dt))
    assert f(np.array([v * dt]), dt)[0] == pytest.approx(a * v * dt)


def test_fast_motion_lags_less_with_a_larger_beta():
    t = np.arange(60) / 30
    ramp = 2.0 * t  # 2 units/s
    lag = {}
    for beta in (0.0, 2.0):
        f = OneEuroFilter(1.0, beta)
        out = np.array([f(np.array([x]), s)[0] for x, s in zip(ramp, t)])
        lag[beta] = ramp[-1] - out[-1]
    assert 0 < lag[2.0] < 0.5 * lag[0.0]


def test_jitter_at_rest_is_damped():
    rng = np.random.default_rng(0)
    noise = rng.normal(scale=0.01, size=(300, 3))
    f = OneEuroFilter(1.0, 0.5)
    out = np.array([f(x, k / 30) for k, x in enumerate(noise)])
    assert np.std(out[30:]) < 0.5 * np.std(noise[30:])


def test_timestamps_that_do_not_advance_fall_back_to_30_hz():
    a, b = OneEuroFilter(1.0, 0.5), OneEuroFilter(1.0, 0.5)
    xs = np.linspace(0, 1, 5)[:, None]
    out_a = [a(x, 0.0) for x in xs]
    out_b = [b(x, k / 30) for k, x in enumerate(xs)]
    assert np.allclose(out_a, out_b)


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="cut-offs"):
        OneEuroFilter(0.0, 0.5)
    with pytest.raises(ValueError, match="beta"):
        OneEuroFilter(1.0, -1.0)


def test_the_pose_filter_keeps_the_root_rotation_unit_and_on_one_hemisphere():
    pose = np.zeros(36)
    pose[ROOT_QUATERNION] = [1.0, 0.0, 0.0, 0.0]
    f = PoseFilter(1.0, 0.5)
    f(pose, 0.0)
    flipped = pose.copy()
    flipped[ROOT_QUATERNION] = [-1.0, 0.0, 0.0, 0.0]  # the same rotation
    out = f(flipped, 1 / 30)
    assert np.allclose(out[ROOT_QUATERNION], [1.0, 0.0, 0.0, 0.0])
    turned = pose.copy()
    turned[ROOT_QUATERNION] = [math.cos(0.3), 0.0, math.sin(0.3), 0.0]
    out = f(turned, 2 / 30)
    assert np.linalg.norm(out[ROOT_QUATERNION]) == pytest.approx(1.0)


@pytest.fixture(scope="module")
def wave(tmp_path_factory):
    out = tmp_path_factory.mktemp("wave")
    config = SynthConfig(frames=5, fps=15.0, seed=2)
    synthesize(load_body("builtin"), builtin_motion("wave", 5, config.fps), out, config, progress=False)
    return out


@pytest.mark.slow
def test_the_tracker_publishes_filtered_poses_and_searches_unfiltered(wave):
    """With --smoothing one-euro the search's solutions are those of an unsmoothed run (same
    seed), and so is the detector's next box; the published poses are the One-Euro filter of
    them and the joints are those poses'."""
    body = load_body("builtin")
    intr = Intrinsics.load(wave / "intrinsic.json")
    plain = BodyTracker(body, intr, TrackerConfig(**SMALL))
    smooth = BodyTracker(body, intr, TrackerConfig(**SMALL, smoothing="one-euro", smoothing_cutoff_hz=1.0,
                                                   smoothing_beta=0.5))
    oracle = PoseFilter(1.0, 0.5)
    moved = []
    for frame, det in frames_of(wave):
        a, b = plain.step(frame, det), smooth.step(frame, det)
        assert a.state == b.state == ("init" if frame.index == 0 else "tracking")
        assert np.array_equal(plain.previous, smooth.previous)  # the search is unaffected
        assert np.array_equal(b.found.pose, a.pose) and np.array_equal(b.joints_box(), a.joints_box())
        expected = oracle(a.pose, frame.timestamp_ns * 1e-9)
        assert np.allclose(b.pose, expected)
        assert np.allclose(b.joints3d, smooth.body.posed_points(expected[None], EVAL_JOINTS)[0])
        moved.append(np.abs(b.pose - a.pose).max())
    assert moved[0] < 1e-12 and max(moved[1:]) > 1e-3  # the filter does act after the first frame
