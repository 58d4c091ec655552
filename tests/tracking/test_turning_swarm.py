"""Offline, a track that turns fast searches its frame with the whole-pose swarm (``turning_swarm``)."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.core.rotations import quaternion_multiply
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.history import TrackHistory


def turned(pose: np.ndarray, degrees: float) -> np.ndarray:
    """``pose`` (36,) with its root turned by ``degrees`` about the body's vertical (body frame Y)."""
    half = np.radians(degrees) / 2
    out = pose.copy()
    out[3:7] = quaternion_multiply(pose[3:7], [np.cos(half), 0.0, np.sin(half), 0.0])
    return out


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


@pytest.fixture(scope="module")
def facing(body) -> np.ndarray:
    return body.rest_pose((0.0, 0.0, 3.0), (0.0, 1.0, 0.0, 0.0))


def test_the_turn_rate_is_the_roots_turn_over_the_time_between_the_last_two_poses(facing):
    history = TrackHistory()
    assert history.turn_rate_deg_s() is None
    history.add(facing, 1_000_000_000)
    assert history.turn_rate_deg_s() is None, "one pose"
    history.add(turned(facing, 12.0), 1_100_000_000)  # 12 degrees in 0.1 s
    assert history.turn_rate_deg_s() == pytest.approx(120.0, rel=1e-6)
    history.add(turned(facing, 12.0), 1_100_000_000)
    assert history.turn_rate_deg_s() is None, "no time between them"
    history.add(turned(facing, 9.0), 1_150_000_000)  # back by 3 degrees in 0.05 s: a rate, whatever the direction
    assert history.turn_rate_deg_s() == pytest.approx(60.0, rel=1e-6)


@pytest.mark.parametrize("degrees, budget_ms, limit, by_blocks", [
    (12.0, 0.0, 90.0, False),  # 120 deg/s offline: the whole swarm
    (6.0, 0.0, 90.0, True),  # 60 deg/s: blocks
    (12.0, 60.0, 90.0, True),  # live frames keep the blocks
    (12.0, 0.0, 0.0, True),  # the setting off
    (12.0, 0.0, 150.0, True),  # under a higher limit
])
def test_a_track_turning_faster_than_the_limit_searches_offline_with_the_whole_swarm(body, facing, degrees,
                                                                                      budget_ms, limit, by_blocks):
    tracker = BodyTracker(body, Intrinsics.kinect_v1(), TrackerConfig(turning_swarm=limit))
    tracker.budget_ms = budget_ms
    assert tracker.searches_by_blocks(), "no poses yet"
    tracker.history.add(facing, 0)
    tracker.history.add(turned(facing, degrees), 100_000_000)
    assert tracker.searches_by_blocks() is by_blocks
