"""Props beside people in the depth (issue 53): which surfaces are props, the memory that confirms
and keeps them, and the segmentation that leaves known ones out; checked against the renderer's
labels of the same scene (person k, -m for prop m)."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.people import segment_people
from swarmpose.detect.props import CONFIRM_FRAMES, PropMemory, match_tolerance
from swarmpose.motion.library import load_motion_spec
from swarmpose.sim.props import parse_prop_spec
from swarmpose.sim.render import Renderer
from swarmpose.sim.scene import PersonSpec, ScenePerson
from swarmpose.sim.synth import SynthConfig, place_scene

KINECT = Intrinsics.kinect_v1()


@pytest.fixture(scope="module")
def body():
    return load_body("builtin", None)


def _render(body, motion: str, frames: int, props: tuple[str, ...], frame: int | None = 0):
    """Depth (H, W) m (noise-free) and labels of ``frame`` (None: where the hips are lowest) of the
    built-in body doing ``motion`` with ``props`` (``--prop`` specs) in the room."""
    config = SynthConfig(frames=frames, fps=15.0, props=tuple(parse_prop_spec(p) for p in props))
    person = ScenePerson(PersonSpec(), body, load_motion_spec(motion, body, frames, 15.0))
    film = place_scene([person], config)
    if frame is None:  # the camera frame's y points down: the lowest hips have the largest y
        frame = int(np.argmax(body.posed_points(film.poses[0], ["mid_hip"])[:, 0, 1]))
    verts = body.pose(film.poses[0][frame:frame + 1], "dqs")[0]
    depth, _, labels = Renderer(KINECT).render_people([(verts, body.triangles)], film.room)
    return depth, labels


def test_a_table_in_front_of_a_person_is_a_prop_and_nothing_else_is(body):
    depth, labels = _render(body, "builtin:wave", 4, ("table",), 0)
    seg = segment_people(depth, KINECT)
    assert len(seg.people) == 1 and seg.rejected.get("too_low") == 1  # the table: 0.75 m high
    table = labels == -1
    assert seg.props is not None
    assert (seg.props & table).sum() > 0.85 * table.sum()  # its pixels but a band along the floor
    assert not (seg.props & (labels >= 0)).any()  # none of the person's, the wall's or the floor's


def test_a_room_without_props_has_none(body):
    depth, labels = _render(body, "builtin:wave", 4, (), 0)
    seg = segment_people(depth, KINECT)
    assert len(seg.people) == 1 and seg.props is None


def test_the_memory_confirms_a_standing_prop_keeps_it_behind_a_person_and_forgets_it_when_gone(body):
    depth, labels = _render(body, "builtin:wave", 4, ("box:0.8,0,0.5,0.5,0.6",), 0)
    box = labels == -1
    rng = np.random.default_rng(0)
    memory = PropMemory()
    for _ in range(CONFIRM_FRAMES):
        noisy = depth + (rng.normal(0, 0.005, depth.shape) * (depth > 0)).astype(np.float32)
        assert memory.known(noisy, KINECT) is None  # not before it stood still CONFIRM_FRAMES frames
        memory.learn(noisy, KINECT, segment_people(noisy, KINECT).props)
    known = memory.known(depth, KINECT)
    assert known is not None and (known & box).sum() > 0.8 * box.sum() and not (known & ~box).any()
    # Someone in front of part of it: the pixels still showing the box are known, the person's are not.
    hidden = depth.copy()
    cols = np.flatnonzero(box.any(axis=0))
    covered = np.zeros(depth.shape, bool)
    covered[:, cols[0]:cols[0] + len(cols) // 2] = True
    hidden[covered & box] -= 0.3
    known = memory.known(hidden, KINECT)
    assert not (known & covered).any() and (known & box & ~covered).sum() > 0.8 * (box & ~covered).sum()
    # Taken away: the wall behind shows where it stood, and the memory lets go of those pixels.
    gone, _ = _render(body, "builtin:wave", 4, (), 0)
    assert memory.known(gone, KINECT) is None and memory.known(depth, KINECT) is None


def test_a_pipeline_reset_forgets_the_props(body):
    from swarmpose.pipeline.step import FramePipeline

    depth, _ = _render(body, "builtin:wave", 4, ("box:0.8,0,0.5,0.5,0.6",), 0)
    pipeline = FramePipeline(None, lambda intrinsics, body_id: None, max_people=2)
    for _ in range(CONFIRM_FRAMES):
        pipeline._props.learn(depth, KINECT, segment_people(depth, KINECT).props)
    assert pipeline._props.known(depth, KINECT) is not None
    pipeline.reset()
    assert pipeline._props.known(depth, KINECT) is None


def test_a_candidate_that_moves_never_becomes_a_prop(body):
    memory = PropMemory()
    for k in range(2 * CONFIRM_FRAMES):
        x = 0.6 + 0.8 * (k % 2)  # a surface moving to and fro (by more than its size) is no furniture
        depth, _ = _render(body, "builtin:wave", 4, (f"box:{x},0,0.5,0.5,0.6",), 0)
        memory.learn(depth, KINECT, segment_people(depth, KINECT).props)
        if k % 2:
            assert memory.known(depth, KINECT) is None


def test_a_known_stool_is_left_out_of_the_person_sitting_on_it(body):
    """The built-in body at the bottom of a squat sits on its automatic stool: the segmentation
    merges the two, unless it is told the stool's pixels are background."""
    depth, labels = _render(body, "builtin:squat", 24, ("stool",), None)
    stool, person = labels == -1, labels == 1
    merged = segment_people(depth, KINECT)
    assert len(merged.people) == 1 and (merged.people[0].mask & stool).sum() > 0.5 * stool.sum()
    alone = segment_people(depth, KINECT, background=stool)
    (segment,) = alone.people
    assert not (segment.mask & stool).any() and (segment.mask & person).sum() > 0.95 * person.sum()
    assert segment.pixels <= merged.people[0].pixels - (merged.people[0].mask & stool).sum()


def test_the_match_tolerance_grows_with_range_as_the_sensor_noise():
    z = np.array([1.0, 2.0, 3.0, 4.0])
    noise = 0.0012 + 0.0019 * (z - 0.4) ** 2  # a Kinect's axial sigma (Nguyen et al. 2012), m
    assert np.all(match_tolerance(z) >= 2.5 * noise) and np.all(match_tolerance(z) <= 6 * noise + 0.01)
