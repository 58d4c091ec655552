"""The automatic height (:mod:`swarmpose.personalise.auto_height`): the uniform scale against the
built-in body built at another stature, when it applies, a tracker that finds a short subject's
height and tracks them better for it, the BVH of the scaled body, and status and info."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ValidatingSink

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_NAMES, EVAL_JOINTS
from swarmpose.personalise.auto_height import ESTIMATES, FACTOR_LIMITS, applies, height_fitting_tracker, scaled_body
from swarmpose.tracking.config import TrackerConfig

FACING = (0.0, 1.0, 0.0, 0.0)  # upright, facing the camera (OpenCV axes: y down)

def test_a_scaled_builtin_body_is_the_builtin_body_built_at_that_stature():
    """Oracle: the parametric body constructed from scratch at 1.55 m (every length of the
    built-in body is proportional to its stature): its named points and its posed skeleton."""
    default = load_body("builtin")
    factor = 1.55 / default.height
    scaled = scaled_body(default, factor)
    built = load_body("builtin", "height=1.55")
    assert scaled.height == pytest.approx(built.height, abs=0.005)
    np.testing.assert_allclose(scaled.bone_heads, built.bone_heads, atol=5e-4)
    joints = list(EVAL_JOINTS)  # the skeleton's joints; the face and foot landmarks are found on the
    pose = default.rest_pose(translation=(0.1, -0.2, 3.0), quaternion=FACING)  # mesh (within 1 cm)
    pose[7:] = np.random.default_rng(1).uniform(-0.3, 0.3, len(ANGLE_NAMES))
    np.testing.assert_allclose(scaled.posed_points(pose[None], joints), built.posed_points(pose[None], joints),
                               atol=5e-4)
    np.testing.assert_allclose(scaled.posed_points(pose[None]), built.posed_points(pose[None]), atol=0.01)


def test_it_applies_only_to_a_body_whose_shape_was_not_given():
    on = TrackerConfig()
    assert applies("builtin", "", on) and applies("makehuman:/x/makehuman", "", on)
    assert not applies("builtin", "female", on)  # the user gave a shape
    assert not applies("me.glb", "", on)  # someone's own body
    assert not applies("builtin", "", TrackerConfig(auto_height=False))
    assert not applies("builtin", "", TrackerConfig(personalize=10))  # the fit does the height
    assert not applies("builtin", "", TrackerConfig(mode="lift"))  # no body to scale


@pytest.mark.slow
def test_a_tracker_finds_a_short_subjects_height_and_tracks_better_for_it(tmp_path, capsys):
    """A 1.55 m built-in subject walking, tracked by the default 1.75 m body: the height found is
    the subject's within 3 cm (oracle: the synthesised body's own stature), and the joints are
    closer to the ground truth than with --no-auto-height (the control)."""
    import json

    from swarmpose.cli.main import main

    seq = tmp_path / "short"
    assert main(["synth", "--body", "builtin", "--shape", "height=1.55", "--motion", "builtin:walk", "--frames", "16",
                 "--out", str(seq), "--quiet"]) == 0
    capsys.readouterr()
    errors = {}
    for switch in ("--auto-height", "--no-auto-height"):
        assert main(["eval", str(seq), "--particles", "32", "--generations", "32", "--max-people", "1", switch,
                     "--json", "--quiet"]) == 0
        errors[switch] = json.loads(capsys.readouterr().out)["mpjpe_mm"]
    assert errors["--auto-height"] < errors["--no-auto-height"] - 5.0, errors

    from swarmpose.detect.registry import make_detector
    from swarmpose.sources.registry import open_source

    source = open_source(str(seq))
    frames = list(source)
    detector = make_detector("simulated", source)
    tracker = height_fitting_tracker(load_body("builtin"), frames[0].intrinsics,  # full resolution: it decimates
                                     TrackerConfig(particles=32, generations=32, max_people=1))
    for frame in frames:
        tracker.step(frame, detector.detect(frame))
    state = tracker.personalisation()
    assert state["state"] == "locked", state
    assert state["height_m"] == pytest.approx(1.55, abs=0.03), state
    assert len(tracker.fitting.factors) == ESTIMATES  # the walk stands upright throughout
    assert FACTOR_LIMITS[0] <= tracker.fitting.factor <= FACTOR_LIMITS[1]
    tracker.new_person()  # another person: the given body again
    assert tracker.personalisation()["state"] == "collecting"
    assert tracker.body.height == pytest.approx(1.75, abs=0.01)
    detector.close()
    source.close()


@pytest.mark.slow
def test_the_bvh_animates_the_scaled_body(tmp_path):
    """`eval --out DIR` with the automatic height: poses.bvh's offsets are the bones of the body
    the tracker scaled (oracle: the given body's rig times the factor the tracker reports), and
    its first row, written before the scale, places the joints where the numpy FK of that frame's
    pose on the scaled rig does."""
    import json
    from contextlib import ExitStack

    from swarmpose.body.kinematics import forward_kinematics
    from swarmpose.cli.main import main
    from swarmpose.motion.bvh import read_bvh
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.run import run_sequence
    from swarmpose.pipeline.service import open_parts
    from swarmpose.publish.bvh_file import bvh_transform

    seq = tmp_path / "short"
    assert main(["synth", "--body", "builtin", "--shape", "height=1.55", "--motion", "builtin:walk", "--frames", "12",
                 "--out", str(seq), "--quiet"]) == 0
    config = ServiceConfig(source=f"folder:{seq}", overlay=False,
                           tracker=TrackerConfig(particles=16, generations=16, max_people=1))
    out = tmp_path / "out"
    with ExitStack() as stack:
        parts = open_parts(config, stack, out=str(out))
        given = parts.body
        run_sequence(parts.source, parts.pipeline, parts.sinks, frames=12, progress=False)
        tracker = parts.pipeline.tracker
    factor = tracker.fitting.factor
    assert tracker.personalisation()["state"] == "locked" and factor < 0.95
    clip = read_bvh(out / "poses.bvh")
    names, parents = given.bone_names, given.rig.parents
    for b in range(1, len(names)):
        np.testing.assert_allclose(clip.offsets[clip.joint_index(names[b])],
                                   100.0 * factor * (given.rig.heads[b] - given.rig.heads[parents[b]]),
                                   atol=2e-3, err_msg=names[b])
    first = json.loads((out / "poses.jsonl").read_text().splitlines()[0])
    _, expected = forward_kinematics(tracker.body.rig, np.array([first["bodies"][0]["pose"]]))
    _, positions = clip.global_transforms()
    order = [clip.joint_index(n) for n in names]
    to_bvh = bvh_transform(first)
    np.testing.assert_allclose(positions[0, order], 100.0 * (expected[0] @ to_bvh[:3, :3].T + to_bvh[:3, 3]),
                               atol=0.05)


@pytest.mark.slow
def test_status_and_info_report_the_height_as_a_personalisation(tmp_path, capsys):
    """A worker run of a 1.55 m built-in subject with the default body: the statuses (valid
    against the schemas) go from collecting to locked, with the scale applied and the body's
    height (oracle: the subject's stature, within 3 cm), and the info message says the same."""
    from contextlib import ExitStack

    from swarmpose.cli.main import main
    from swarmpose.messages import validate
    from swarmpose.messages.build import info_message
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.service import open_parts
    from swarmpose.pipeline.worker import Worker
    from swarmpose.sources.registry import open_source

    seq = tmp_path / "short"
    assert main(["synth", "--body", "builtin", "--shape", "height=1.55", "--motion", "builtin:walk", "--frames", "14",
                 "--out", str(seq), "--quiet"]) == 0
    capsys.readouterr()
    uri = f"folder:{seq}"
    config = ServiceConfig(source=uri, tracker=TrackerConfig(particles=16, generations=16, max_people=1))
    sink = ValidatingSink()
    with ExitStack() as stack:
        parts = open_parts(config, stack)
        worker = Worker(lambda: open_source(uri), parts.pipeline, [sink], camera="test", drop_stale=False,
                        source_uri=uri, status_period_s=0.05, source=parts.source)
        worker.run()
        bodies = [(s["tracker"].get("personalisation", {}).get("bodies") or [{}])[0] for s in sink.statuses]
        states = [b.get("state") for b in bodies]
        assert "collecting" in states and states[-1] == "locked", states
        locked = bodies[-1]
        assert locked["frames"] == locked["needed"] == ESTIMATES
        assert locked["height_m"] == pytest.approx(1.55, abs=0.03), locked
        assert locked["parameters"]["scale"] == pytest.approx(locked["height_m"] / parts.body.height, abs=1e-3)
        info = validate(info_message("test", body=parts.pipeline.tracker.body, body_spec=config.body,
                                     personalisation=parts.pipeline.personalisation))
        assert info["body"]["personalisation"]["bodies"][0] == locked
