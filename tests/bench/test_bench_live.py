"""``bench live``: its figures against a log worked out by hand, and one real run of the worker."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.bench.live import LiveLog, Published, accuracy_figures, bench_live, stage_split, steady_latencies
from swarmpose.publish.pose_at import HORIZON_S
from swarmpose.sources.groundtruth import GroundTruth

J = 14


def _truth(frames: int) -> GroundTruth:
    """Every joint of frame f at x = 0.1 f m: a person moving at 1 m/s filmed at 10 frames/s."""
    joints = np.zeros((frames, J, 3))
    joints[:, :, 0] = 0.1 * np.arange(frames)[:, None]
    return GroundTruth(tuple(range(frames)), np.zeros((frames, 36)), joints, (None,) * frames)


def _published(frame: int, received_s: float, publish_s: float, truth: GroundTruth) -> Published:
    joints = truth.joints3d[frame] + [0.01, 0.0, 0.0]  # 10 mm off in x
    velocity = np.tile([1.0, 0.0, 0.0], (J, 1))
    return Published(0, frame, int(received_s * 1e9), int(publish_s * 1e9), (publish_s - received_s) * 1000,
                     {0: joints}, {0: velocity}, {"detect": 2.0, "pso": 30.0, "polish": 5.0, "total": 40.0}, 1.5)


def test_live_client_floor_and_extrapolated_deltas_are_those_worked_out_by_hand():
    truth = _truth(6)
    log = LiveLog()
    log.acquired = [(0, k, int(0.1 * k * 1e9)) for k in range(6)]  # frames 0..5 at 0.0 .. 0.5 s
    log.published = [_published(0, 0.0, 0.05, truth), _published(3, 0.3, 0.35, truth)]
    figures = accuracy_figures(log, truth)
    assert figures["live_mm"] == pytest.approx(10.0)
    # frames 1, 2, 3 see frame 0's pose (x = 0.01), frames 4, 5 frame 3's (x = 0.31); frame 0 sees none yet
    assert figures["client_mm"] == pytest.approx((90 + 190 + 290 + 90 + 190) / 5)
    assert figures["client_floor_mm"] == pytest.approx((100 + 200 + 300 + 100 + 200) / 5)
    # moved on at 1 m/s for at most HORIZON_S: frame k sees the pose of frame j moved by min(dt, HORIZON_S)
    seen = [(0.01, 0.1, 0.1), (0.01, 0.2, 0.2), (0.01, 0.3, 0.3), (0.31, 0.4, 0.1), (0.31, 0.5, 0.2)]  # x, truth, dt
    expected = [1000 * abs(x + min(dt, HORIZON_S) - truth) for x, truth, dt in seen]
    assert figures["client_extrapolated_mm"] == pytest.approx(sum(expected) / len(expected))
    assert figures["missed"] == 0
    split = stage_split(log)
    assert split["search"] == 30.0 and split["polish"] == 5.0 and split["publish"] == 1.5 and split["total"] == 40.0


def test_a_published_frame_without_the_person_is_a_miss_not_an_error():
    truth = _truth(2)
    log = LiveLog()
    log.acquired = [(0, 0, 0), (0, 1, int(1e8))]
    log.published = [Published(0, 0, 0, int(5e7), 50.0, {}, {}, {}, 0.0), _published(1, 0.1, 0.12, truth)]
    figures = accuracy_figures(log, truth)
    assert figures["missed"] == 1 and figures["live_mm"] == pytest.approx(10.0)


@pytest.mark.slow
def test_a_short_live_run_publishes_poses_near_the_truth(side_wave):
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.tracking.config import TrackerConfig

    config = ServiceConfig(source=str(side_wave), detector="simulated", overlay=False, rate=10.0,  # 2 s a pass
                           tracker=TrackerConfig(particles=16, generations=8, polish=4, max_people=1))
    result = bench_live(config, seconds=2.0, offline=True, startup=False)
    assert result["poses"] >= 3 and result["poses_per_s"] > 0
    assert result["latency_ms"]["p95"] >= result["latency_ms"]["median"] > 0
    assert result["starts"] >= 1, "the track started at least once"
    assert result["live_mm"] < 150 and result["offline_mm"] < 150
    assert result["client_floor_mm"] is not None and result["stage_ms"]["search"] > 0


def test_steady_latencies_leave_out_the_second_after_each_start():
    truth = _truth(40)
    log = LiveLog()
    for k in range(40):  # frames every 0.1 s, each 100 ms late; a start at 0.0 s and at 2.0 s
        p = _published(k, 0.1 * k, 0.1 * k + 0.1, truth)
        if k in (0, 20):
            p.timings_ms["init"] = 500.0
        log.published.append(p)
    steady, starts = steady_latencies(log, settle_s=1.0)
    assert starts == 2
    assert len(steady) == 40 - 2 * 10, "frames 0-9 and 20-29 are within a second of a start"
    assert steady == pytest.approx([100.0] * 20)
    assert steady_latencies(LiveLog())[0] == []


def test_camera_frames_of_a_new_pass_before_its_first_pose_are_left_out_of_the_client_figures():
    truth = _truth(4)
    log = LiveLog()
    log.acquired = [(0, 0, 0), (0, 1, int(1e8)), (1, 0, int(2e8)), (1, 1, int(3e8))]  # looped after frame 1
    log.published = [_published(0, 0.0, 0.05, truth)]  # the new pass has no pose yet
    figures = accuracy_figures(log, truth)
    assert figures["client_frames_left_out"] == 2
    assert figures["client_mm"] == pytest.approx(90.0)  # frame 1 only: frame 0's pose, 0.09 m behind
