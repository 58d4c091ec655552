"""Live, a person tracked alone is segmented on every SEGMENT_ALONE_EVERY-th frame only; the frames
between are detected whole, and the tracker is given the same depth either way."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import synthesize_scene

import swarmpose
from swarmpose.cli.main import main
from swarmpose.detect.people import segment_people
from swarmpose.people.people_tracker import PeopleTracker, Track
from swarmpose.pipeline.step import SEGMENT_ALONE_EVERY
from swarmpose.sources.folder import FolderSource
from swarmpose.tracking.body_tracker import BodyTracker

FRAMES = 9
FAST = {"detector": "simulated", "max_people": 4, "particles": 8, "generations": 8}


def segmented_frames(results) -> list[int]:
    return [r.index for r in results if "segment" in r.timings_ms and r.timings_ms["segment"] > 0]


def tracked(folder, live: bool, monkeypatch, reset_at: int | None = None):
    """The results of every frame of ``folder`` through the per-frame step (``live``: a frame period
    set, as ``serve`` does), per tracker call whether the depth it got was the frame's own, and the
    frames the pipeline said beforehand it would segment (:meth:`FramePipeline.segments_next`)."""
    own_depth, depths, predicted = [], {}, []
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
            if tracker.pipeline.segments_next():
                predicted.append(frame.index)
            results.append(tracker.track_frame(frame))
    return results, own_depth, predicted


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    return synthesize_scene(tmp_path_factory.mktemp("alone"), ("builtin:male:builtin:walk@0.0,0.0",), FRAMES, seed=2)


@pytest.fixture(scope="module")
def beside_a_box(tmp_path_factory):
    out = tmp_path_factory.mktemp("box")
    assert main(["synth", "--motion", "builtin:wave", "--frames", "6", "--prop", "box:0.7,0.0,0.4,0.4,0.5",
                 "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    return synthesize_scene(tmp_path_factory.mktemp("two"), ("builtin:male:builtin:walk@-0.7,0.3",
                                                             "builtin:female:builtin:wave@0.6,-0.6"), 5, seed=3)


def test_live_a_lone_person_is_segmented_every_few_frames_and_fitted_on_the_same_depth(walk, monkeypatch):
    results, own_depth, predicted = tracked(walk, True, monkeypatch)
    assert SEGMENT_ALONE_EVERY == 4
    assert segmented_frames(results) == predicted == [0, 4, 8]
    assert all(len([b for b in r.bodies if b.state != "lost"]) == 1 for r in results)
    assert [r.people["found"] for r in results] == [1] * FRAMES  # an unsegmented frame: the one found alone
    assert [b.id for r in results for b in r.bodies] == [0] * FRAMES
    assert len(own_depth) == FRAMES and all(own_depth)  # nothing left out of a lone person's depth either way


def test_offline_every_frame_is_segmented(walk, monkeypatch):
    results, _, predicted = tracked(walk, False, monkeypatch)
    assert segmented_frames(results) == predicted == list(range(FRAMES))


def test_a_reset_segments_the_next_frame(walk, monkeypatch):
    results, _, predicted = tracked(walk, True, monkeypatch, reset_at=2)
    assert segmented_frames(results) == predicted == [0, 2, 6]


def test_live_two_people_are_segmented_every_frame(two, monkeypatch):
    results, own_depth, predicted = tracked(two, True, monkeypatch)
    assert segmented_frames(results) == predicted == list(range(5))
    assert max(len(r.bodies) for r in results) == 2
    assert not all(own_depth)  # each person's depth leaves the other out


def test_live_a_person_beside_a_prop_is_segmented_every_frame(beside_a_box, monkeypatch):
    """The box beside the person is a prop candidate from the first frame, then a prop the memory
    knows: the frame is not one of a person alone, so every frame is segmented (the prop stays out
    of the fit's depth)."""
    first = next(iter(FolderSource(beside_a_box)))
    assert segment_people(first.depth, first.intrinsics).props is not None  # the box is beside the person
    results, own_depth, predicted = tracked(beside_a_box, True, monkeypatch)
    assert segmented_frames(results) == predicted == list(range(6))
    assert not all(own_depth)  # the confirmed prop left out of the depth


def test_a_fit_judged_lost_leaves_the_tracks_centre_and_velocity_as_they_were():
    """A whole-frame detection (no segment) places the track at its fit's joints, but not a fit judged
    lost: its pose may lie anywhere, and the next segmented frame must still find the person."""
    from dataclasses import replace

    from swarmpose.tracking.result import lost_body

    track = Track(0, None, np.array([0.0, 0.0, 3.0]), velocity=np.array([0.01, 0.0, 0.0]), last_frame=4)
    far = np.tile([1.5, 0.0, 4.0], (14, 1))  # the rejected pose's joints, as a lost verdict keeps them
    lost = replace(lost_body("2D joints off", 0, {}), joints3d=far)
    assert np.all(np.isfinite(PeopleTracker._fit_centre(lost, np.zeros(3))))  # a fit centre it could take
    centre = PeopleTracker._observed_centre(PeopleTracker.__new__(PeopleTracker), np.full(3, np.nan), lost)
    track.seen(centre, None, 5)
    np.testing.assert_array_equal(track.centre, [0.0, 0.0, 3.0])
    np.testing.assert_array_equal(track.velocity, [0.01, 0.0, 0.0])
    assert track.last_frame == 5 and track.missed == 0
