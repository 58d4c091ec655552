"""Live, a person tracked alone is segmented on every SEGMENT_ALONE_EVERY-th frame only; the frames
between are detected whole, and the tracker is given the same depth either way."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import synthesize_scene

import swarmpose
from swarmpose.pipeline.step import SEGMENT_ALONE_EVERY
from swarmpose.sources.folder import FolderSource
from swarmpose.tracking.body_tracker import BodyTracker

FRAMES = 9
FAST = {"detector": "simulated", "max_people": 4, "particles": 8, "generations": 8}


def segmented_frames(results) -> list[int]:
    return [r.index for r in results if "segment" in r.timings_ms and r.timings_ms["segment"] > 0]


def tracked(folder, live: bool, monkeypatch, reset_at: int | None = None):
    """The results of every frame of ``folder`` through the per-frame step (``live``: a frame period
    set, as ``serve`` does), and per tracker call whether the depth it got was the frame's own."""
    own_depth, depths = [], {}
    real = BodyTracker.step

    def step(tracker, frame, *args, **kwargs):
        own_depth.append(np.array_equal(frame.depth, depths[frame.index]))
        return real(tracker, frame, *args, **kwargs)

    monkeypatch.setattr(BodyTracker, "step", step)
    source = FolderSource(folder)
    results = []
    with swarmpose.Tracker(source=source, **FAST) as tracker:
        tracker.pipeline.frame_period_s = 1 / 30 if live else None
        for frame in source:
            if frame.index == reset_at:
                tracker.pipeline.reset()
            depths[frame.index] = frame.depth.copy()
            results.append(tracker.track_frame(frame))
    return results, own_depth


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    return synthesize_scene(tmp_path_factory.mktemp("alone"), ("builtin:male:builtin:walk@0.0,0.0",), FRAMES, seed=2)


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    return synthesize_scene(tmp_path_factory.mktemp("two"), ("builtin:male:builtin:walk@-0.7,0.3",
                                                             "builtin:female:builtin:wave@0.6,-0.6"), 5, seed=3)


def test_live_a_lone_person_is_segmented_every_few_frames_and_fitted_on_the_same_depth(walk, monkeypatch):
    results, own_depth = tracked(walk, True, monkeypatch)
    assert SEGMENT_ALONE_EVERY == 4
    assert segmented_frames(results) == [0, 4, 8]
    assert all(len([b for b in r.bodies if b.state != "lost"]) == 1 for r in results)
    assert [r.people["found"] for r in results] == [1] * FRAMES  # an unsegmented frame: the one found alone
    assert [b.id for r in results for b in r.bodies] == [0] * FRAMES
    assert len(own_depth) == FRAMES and all(own_depth)  # nothing left out of a lone person's depth either way


def test_offline_every_frame_is_segmented(walk, monkeypatch):
    results, _ = tracked(walk, False, monkeypatch)
    assert segmented_frames(results) == list(range(FRAMES))


def test_a_reset_segments_the_next_frame(walk, monkeypatch):
    results, _ = tracked(walk, True, monkeypatch, reset_at=2)
    assert segmented_frames(results) == [0, 2, 6]


def test_live_two_people_are_segmented_every_frame(two, monkeypatch):
    results, own_depth = tracked(two, True, monkeypatch)
    assert segmented_frames(results) == list(range(5))
    assert max(len(r.bodies) for r in results) == 2
    assert not all(own_depth)  # each person's depth leaves the other out
