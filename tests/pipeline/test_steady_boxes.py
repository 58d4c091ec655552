"""The detector's crop box held while the tracked person stays put (``box_hold``, issue 53).

Oracles: boxes worked out by hand for :class:`SteadyBoxes`; for the pipeline, the boxes the real
simulated detector is handed on a synthetic person standing still (a held frame): one box while
still with the hold, a new box each frame without it.
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

SMALL = TrackerConfig(particles=12, generations=8, polish=0)


def test_a_box_is_held_while_each_edge_moves_less_than_the_share_of_its_larger_side():
    steady = SteadyBoxes(0.05)  # a 100 x 200 px box: edges may move 10 px
    first = np.array([100.0, 50.0, 200.0, 250.0])
    assert np.array_equal(steady.update({1: first})[1], first)
    assert np.array_equal(steady.update({1: first + [9.9, -9.9, 5.0, 0.0]})[1], first)
    moved = first + [0.0, 0.0, 10.5, 0.0]  # one edge 10.5 px: the new box, and it is held from then on
    assert np.array_equal(steady.update({1: moved})[1], moved)
    assert np.array_equal(steady.update({1: first + [0.0, 0.0, 12.0, 0.0]})[1], moved)
    # another track has its own box; a track without a box (lost) is forgotten
    out = steady.update({1: None, 2: first})
    assert list(out) == [2] and np.array_equal(out[2], first)
    assert np.array_equal(steady.update({1: first + 1.0})[1], first + 1.0)
    off = SteadyBoxes(0.0)
    off.update({1: first})
    assert np.array_equal(off.update({1: first + 1.0})[1], first + 1.0)
    with pytest.raises(ValueError, match="box hold share"):
        SteadyBoxes(-0.1)


class BoxRecorder:
    """The real detector, noting the box it is asked to look in."""

    def __init__(self, inner):
        self.inner, self.boxes = inner, []

    def detect(self, frame, box=None):
        self.boxes.append(None if box is None else np.array(box, dtype=float))
        return self.inner.detect(frame, box)

    def close(self):
        self.inner.close()


@pytest.fixture(scope="module")
def still_person(tmp_path_factory):
    out = tmp_path_factory.mktemp("still")
    assert main(["synth", "--motion", "builtin:wave?hold=0.3", "--frames", "8", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("share", [0.05, 0.0])
def test_the_detector_looks_in_one_box_while_the_person_stands_still(still_person, share):
    body = load_body("builtin")
    source = open_source(f"folder:{still_person}")
    detector = BoxRecorder(make_detector("simulated", source))
    pipeline = FramePipeline(detector, lambda intrinsics, body_id: BodyTracker(body, intrinsics, SMALL, body_id),
                             max_people=1, box_hold=share)
    for frame in source:
        assert pipeline.process(frame).bodies[0].state != "lost"
    boxes = detector.boxes
    assert boxes[0] is None and len(boxes) == 8  # the first frame: the whole image
    still = boxes[1:]  # frames 1..7 are looked at where frames 0..6 were tracked: all held still (9 frames)
    changes = sum(not np.array_equal(a, b) for a, b in zip(still, still[1:]))
    # without the hold, the tracked joints move by a fraction of a pixel each frame, and their box with them
    assert changes == (0 if share else len(still) - 1)
