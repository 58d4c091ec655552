"""DetectorThread with real detectors: newest-frame semantics, drops, rate, ages, errors, shutdown."""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, needs_assets
from swarmpose.camera import Intrinsics
from swarmpose.errors import ConfigError, DetectorError
from swarmpose.joints2d.registry import make_detector
from swarmpose.joints2d.thread import DetectorThread
from swarmpose.sources.base import Frame

INTR = Intrinsics.kinect_v1()
FRAME_NS = 33_333_333


def _frame(index: int, color: np.ndarray | None = None) -> Frame:
    return Frame(index, 1_000_000 + index * FRAME_NS, np.zeros((480, 640), np.float32), color, INTR)


@pytest.fixture
def openpose_dir(tmp_path) -> Path:
    """OpenPose files for frames 0..9: person with nose at x = 100 + frame; frame 5's file is corrupt."""
    for i in range(10):
        path = tmp_path / f"run_{i:012d}_keypoints.json"
        if i == 5:
            path.write_text('{"people": [{"pose_keypoints_2d": [1, 2, 0.5,')
        else:
            path.write_text(json.dumps({"people": [{"pose_keypoints_2d": [100.0 + i, 50.0, 0.9] * 25}]}))
    return tmp_path


def test_only_the_newest_pending_frame_is_detected(openpose_dir):
    with DetectorThread(make_detector(f"openpose-json:{openpose_dir}"), rate_hz=4.0) as thread:
        assert thread.latest() is None and thread.age_ns(_frame(0)) is None and thread.wall_age_s() is None
        assert thread.submit(_frame(0)) is False
        assert thread.wait_idle(5.0)
        assert thread.latest().frame_index == 0
        # The next detection may start 0.25 s after the first: frames 1..8 are replaced while pending.
        dropped = [thread.submit(_frame(i)) for i in (1, 2, 3, 4, 6, 7, 8, 9)]
        assert dropped == [False] + [True] * 7
        assert thread.wait_idle(5.0)
        latest = thread.latest()
        assert latest.frame_index == 9 and latest.keypoints[0].tolist() == [109.0, 50.0, 0.9]
        assert (thread.submitted, thread.processed, thread.dropped, thread.errors) == (9, 2, 7, 0)


def test_rate_limits_how_often_the_detector_runs(openpose_dir):
    with DetectorThread(make_detector(f"openpose-json:{openpose_dir}"), rate_hz=2.5) as thread:
        t0 = time.monotonic()
        for i in range(3):
            thread.submit(_frame(i))
            assert thread.wait_idle(5.0)
        assert time.monotonic() - t0 >= 2 * 0.4 - 0.01  # three detections need at least two intervals
        assert thread.processed == 3
    with DetectorThread(make_detector(f"openpose-json:{openpose_dir}")) as unlimited:
        t0 = time.monotonic()
        for i in range(3):
            unlimited.submit(_frame(i))
            assert unlimited.wait_idle(5.0)
        assert time.monotonic() - t0 < 0.4


def test_ages_relative_to_a_frame_and_to_the_wall_clock(openpose_dir):
    with DetectorThread(make_detector(f"openpose-json:{openpose_dir}")) as thread:
        thread.submit(_frame(2))
        assert thread.wait_idle(5.0)
        assert thread.age_ns(_frame(5)) == 3 * FRAME_NS
        assert thread.age_ns(_frame(2)) == 0
        first = thread.wall_age_s()
        time.sleep(0.05)
        assert 0 <= first < thread.wall_age_s()
        assert thread.wall_age_s() >= 0.05


def test_a_failing_frame_is_counted_and_the_thread_goes_on(openpose_dir):
    with DetectorThread(make_detector(f"openpose-json:{openpose_dir}")) as thread:
        thread.submit(_frame(4))
        assert thread.wait_idle(5.0)
        thread.submit(_frame(5))  # corrupt file
        assert thread.wait_idle(5.0)
        assert thread.errors == 1 and isinstance(thread.last_error, DetectorError)
        assert "run_000000000005_keypoints.json" in str(thread.last_error)
        assert thread.latest().frame_index == 4 and thread.alive
        thread.submit(_frame(6))
        assert thread.wait_idle(5.0)
        assert thread.latest().frame_index == 6 and thread.processed == 2
        stats = thread.stats()
        assert stats["errors"] == 1 and "run_000000000005" in stats["last_error"]


def test_close_stops_joins_and_drops_the_pending_frame(openpose_dir):
    detector = make_detector(f"openpose-json:{openpose_dir}")
    thread = DetectorThread(detector, rate_hz=0.5)
    thread.submit(_frame(0))
    assert thread.wait_idle(5.0)
    thread.submit(_frame(1))  # waits 2 s for its turn
    t0 = time.monotonic()
    thread.close()
    assert time.monotonic() - t0 < 1.0  # the waiting thread woke up at once
    assert not thread.alive
    assert (thread.submitted, thread.processed, thread.dropped) == (2, 1, 1)
    thread.close()  # idempotent
    with pytest.raises(DetectorError, match="closed"):
        thread.submit(_frame(2))
    assert thread.latest().frame_index == 0  # the last result stays readable


@needs_assets
def test_movenet_in_its_thread_matches_a_direct_detection():
    photo = cv2.cvtColor(cv2.imread(str(ASSETS / "images" / "coco_val2017_000000000785.jpg")), cv2.COLOR_BGR2RGB)
    frame = Frame(7, 123_000, np.zeros(photo.shape[:2], np.float32), photo,
                  Intrinsics(640, 425, 500.0, 500.0, 319.5, 212.0))
    spec = f"onnx:{ASSETS / 'pose2d' / 'movenet_singlepose_lightning.onnx'}"
    direct = make_detector(spec).detect(frame)
    detector = make_detector(spec)
    with DetectorThread(detector) as thread:
        for _ in range(3):
            thread.submit(frame)
        assert thread.wait_idle(10.0)
        latest = thread.latest()
        assert thread.submitted == thread.processed + thread.dropped == 3 and thread.errors == 0
    assert not thread.alive and detector.session is None  # closing the thread closed the detector
    assert (latest.frame_index, latest.timestamp_ns) == (7, 123_000)
    np.testing.assert_allclose(latest.keypoints, direct.keypoints, atol=1e-4)


@pytest.mark.parametrize("rate", [0.0, -1.0, float("nan"), float("inf")])
def test_a_bad_rate_is_refused(openpose_dir, rate):
    with pytest.raises(ConfigError, match="rate"):
        DetectorThread(make_detector(f"openpose-json:{openpose_dir}"), rate_hz=rate)
