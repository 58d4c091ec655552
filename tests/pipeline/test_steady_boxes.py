"""The detector's crop box held while the tracked person stays put (``box_hold``, issue 53).

Oracles: boxes worked out by hand for :class:`SteadyBoxes`; for the pipeline, the boxes the real
simulated detector is handed on a synthetic person standing still (a held frame): the first box
again once the box has stayed within the share for 5 frames, a new box each frame without it.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.cli.main import main
from swarmpose.detect.registry import make_detector
from swarmpose.detect.steady_boxes import SteadyBoxes
from swarmpose.pipeline.step import FramePipeline
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

SMALL = TrackerConfig(particles=12, generations=8, polish=0, search="swarm")
"""The whole-pose swarm moves a still person's pose by a fraction of a pixel every frame, the drift
the box hold is there to keep from the detector (the block search may keep it exactly)."""


def test_a_box_is_held_once_it_has_stayed_within_the_share_of_its_larger_side():
    steady = SteadyBoxes(0.05, still_frames=2)  # a 100 x 200 px box: edges may move 10 px, held after 2 frames
    first = np.array([100.0, 50.0, 200.0, 250.0])
    near, nearer = first + [9.9, -9.9, 5.0, 0.0], first + [-5.0, 0.0, 0.0, 3.0]
    assert np.array_equal(steady.update({1: first})[1], first)  # the anchor
    assert np.array_equal(steady.update({1: near})[1], near)  # within it once: as given
    assert np.array_equal(steady.update({1: nearer})[1], first)  # twice running: the anchor, held
    assert np.array_equal(steady.update({1: near})[1], first)
    moved = first + [0.0, 0.0, 10.5, 0.0]  # one edge past 10 px: as given, the new anchor
    assert np.array_equal(steady.update({1: moved})[1], moved)
    assert np.array_equal(steady.update({1: first})[1], first)  # within 10 px of the new anchor, once
    # another track has its own box; a track without a box (lost) is forgotten
    out = steady.update({1: None, 2: first})
    assert list(out) == [2] and np.array_equal(out[2], first)
    assert list(steady.anchors) == [2]
    off = SteadyBoxes(0.0, still_frames=0)
    for k in range(3):
        assert np.array_equal(off.update({1: first + k})[1], first + k)
    with pytest.raises(ValueError, match="box hold share"):
        SteadyBoxes(-0.1)


class BoxRecorder:
    """The real detector, noting the box it is asked to look in, and its calls."""

    def __init__(self, inner):
        self.inner, self.boxes, self.calls = inner, [], []

    def detect(self, frame, box=None):
        self.boxes.append(None if box is None else np.array(box, dtype=float))
        self.calls.append("detect")
        return self.inner.detect(frame, box)

    def reset(self):
        self.calls.append("reset")

    def close(self):
        self.inner.close()


@pytest.fixture(scope="module")
def still_person(tmp_path_factory):
    out = tmp_path_factory.mktemp("still")
    assert main(["synth", "--motion", "builtin:wave?hold=0.4", "--frames", "10", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("share", [0.02, 0.0])
def test_the_detector_looks_in_one_box_while_the_person_stands_still(still_person, share):
    body = load_body("builtin")
    source = open_source(f"folder:{still_person}")
    detector = BoxRecorder(make_detector("simulated", source))
    pipeline = FramePipeline(detector, lambda intrinsics, body_id: BodyTracker(body, intrinsics, SMALL, body_id),
                             max_people=1, box_hold=share)
    for frame in source:
        assert pipeline.process(frame).bodies[0].state != "lost"
    boxes = detector.boxes
    assert boxes[0] is None and len(boxes) == 10  # the first frame: the whole image
    still = boxes[1:]  # frames 1..9 are looked at where frames 0..8 were tracked: all held still (12 frames)
    # without the hold, the tracked joints move by a fraction of a pixel each frame, and their box with them
    changes = [not np.array_equal(a, b) for a, b in zip(still, still[1:])]
    if not share:
        assert all(changes)
    else:  # frame 0's box is the anchor; frames 1..4 stay near it and are given as they are; from frame 5 on, held
        assert all(changes[:4]) and all(np.array_equal(b, still[0]) for b in still[5:])


def test_a_reset_pipeline_resets_its_detector_before_the_next_detection(still_person):
    """A camera that came back or a recording that starts over: the detector forgets its crops (BlazePose
    its regions) once, in the detection's own call, before looking at the next frame as a whole."""
    body = load_body("builtin")
    source = open_source(f"folder:{still_person}")
    detector = BoxRecorder(make_detector("simulated", source))
    pipeline = FramePipeline(detector, lambda intrinsics, body_id: BodyTracker(body, intrinsics, SMALL, body_id),
                             max_people=1)
    frames = list(source)[:4]
    for frame in frames[:2]:
        pipeline.process(frame)
    pipeline.reset()
    for frame in frames[2:]:
        pipeline.process(frame)
    assert detector.calls == ["detect", "detect", "reset", "detect", "detect"]
    assert detector.boxes[1] is not None and detector.boxes[2] is None
