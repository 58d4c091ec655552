"""Jitter, lag and onset Δ of a still-then-moving track (issue 53), against hand computation."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.core.errors import ConfigError
from swarmpose.sim.steadiness import jitter_mm, motion_lag_ms, still_report

FPS = 30.0


def test_jitter_is_each_joints_rms_distance_from_its_mean_position():
    x = np.zeros((4, 3, 3))
    x[:, 0, 0] = [0.003, -0.003, 0.003, -0.003]  # +-3 mm along x: 3 mm
    x[1::2, 1] = [0.003, 0.004, 0.0]  # two places 5 mm apart: each 2.5 mm from their middle
    x[:, 2] = [[1.0, 2.0, 3.0]] * 4  # still: 0
    assert np.allclose(jitter_mm(x), [3.0, 2.5, 0.0])
    x[0, 1] = np.nan  # an unknown frame is left out: 3 of the frames, mean (2, 8/3, 0) mm
    d = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [3.0, 4.0, 0.0]]) - [2.0, 8.0 / 3.0, 0.0]
    assert jitter_mm(x)[1] == pytest.approx(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))
    x[1:, 2] = np.nan  # one known frame: no jitter to speak of
    assert np.isnan(jitter_mm(x)[2])
    with pytest.raises(ConfigError, match="frames, joints, 3"):
        jitter_mm(np.zeros((4, 3)))


def _still_then_moving(frames: int, moves_at: int, delay_s: float) -> np.ndarray:
    """(frames, 2, 3): joint 0 still, joint 1 at rest, then accelerating along x and y from frame
    ``moves_at`` (1 m/s^2 along x, 0.5 along y), shown ``delay_s`` late."""
    t = np.arange(frames) / FPS - moves_at / FPS + 1.0 / FPS - delay_s  # the truth leaves rest after frame moves_at-1
    s = np.where(t > 0, 0.5 * t * t, 0.0)
    out = np.zeros((frames, 2, 3))
    out[:, 0] = [0.1, 0.2, 3.0]
    out[:, 1] = np.stack([0.3 + s, 0.5 * s, np.full(frames, 3.0)], axis=1)
    return out


@pytest.mark.parametrize("delay_ms", [0.0, 50.0, 100.0, -30.0])
def test_the_lag_is_the_delay_of_the_track_behind_the_truth(delay_ms):
    truth = _still_then_moving(60, 30, 0.0)
    track = _still_then_moving(60, 30, delay_ms / 1000.0) + [0.01, -0.02, 0.005]  # and a constant offset
    assert motion_lag_ms(track, truth, 30, FPS, still_from=5) == pytest.approx(delay_ms, abs=2.0)


def test_a_track_with_jitter_lags_as_much_as_without():
    rng = np.random.default_rng(1)
    truth = _still_then_moving(60, 30, 0.0)
    track = _still_then_moving(60, 30, 0.05) + rng.normal(0.0, 0.002, (60, 2, 3))
    assert motion_lag_ms(track, truth, 30, FPS, still_from=5) == pytest.approx(50.0, abs=8.0)


def test_a_joint_that_jumps_does_not_move_the_lag_and_a_joint_that_stays_has_none():
    truth = _still_then_moving(60, 30, 0.0)
    track = _still_then_moving(60, 30, 0.05)
    truth, track = np.concatenate([truth, truth[:, 1:] * [1, -1, 1]], axis=1), np.concatenate(
        [track, track[:, 1:] * [1, -1, 1]], axis=1)  # joints 1 and 2 move (mirrored), joint 0 stays
    truth, track = np.concatenate([truth, truth[:, 1:2]], axis=1), np.concatenate([track, track[:, 1:2]], axis=1)
    track[36:41, 3] += [0.0, 0.2, 0.0]  # joint 3, a hidden limb, jumps 20 cm for 5 frames of the window
    assert motion_lag_ms(track, truth, 30, FPS, still_from=5) == pytest.approx(50.0, abs=2.0)
    still = np.repeat(truth[:1], 60, axis=0)  # nothing moves: no lag to measure
    assert np.isnan(motion_lag_ms(still, still, 30, FPS))


def test_the_report_of_a_track_offset_by_a_constant():
    truth = _still_then_moving(60, 30, 0.0)
    track = truth + [0.0, 0.006, 0.008]  # 10 mm off everywhere, no jitter, no lag
    track[2, 0] += 0.5  # a wild start, left out by settle
    report = still_report(track, truth, 30, FPS, settle=5, joint_names=("a", "b"))
    assert report["jitter_per_joint_mm"] == pytest.approx([0.0, 0.0], abs=1e-9)
    assert report["still_delta_mm"] == pytest.approx(10.0)
    assert report["onset_delta_mm"] == pytest.approx(10.0) and report["moving_delta_mm"] == pytest.approx(10.0)
    assert report["lag_ms"] == pytest.approx(0.0, abs=1.0)
    assert report["jitter_worst"] in ("a", "b")
    track[10:30:2, 1, 0] += 0.004  # joint b: 4 mm out on every other still frame: 2 mm about its mean
    report = still_report(track, truth, 30, FPS, settle=10, joint_names=("a", "b"))
    assert report["jitter_per_joint_mm"][1] == pytest.approx(2.0) and report["jitter_worst"] == "b"
    assert report["jitter_mm"] == pytest.approx(1.0) and report["jitter_max_mm"] == pytest.approx(2.0)


def test_a_lost_track_has_no_lag_and_too_short_sequences_are_refused():
    truth = _still_then_moving(60, 30, 0.0)
    track = truth.copy()
    track[32] = np.nan
    assert still_report(track, truth, 30, FPS, settle=5)["lag_ms"] is None
    with pytest.raises(ConfigError, match="frames of motion"):
        motion_lag_ms(truth[:40], truth[:40], 30, FPS)
    with pytest.raises(ConfigError, match="still frames"):
        motion_lag_ms(truth, truth, 4, FPS)
    with pytest.raises(ConfigError, match="fewer than 2 frames"):
        still_report(truth, truth, 30, FPS, settle=29)
