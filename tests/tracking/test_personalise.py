"""Personalisation: key frames, the bone-length term, and a whole fit on a synthetic subject
whose true shape is known (the oracle: the subject's own MakeHuman body)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP, ValidatingSink, needs_assets

from swarmpose.tracking.personalise import bone_energy, spread_frames


def test_key_frames_are_spread_over_the_poses():
    poses = np.zeros((10, 36))
    poses[:, 3] = 1.0
    poses[:5, 7] = np.linspace(0.0, 0.04, 5)   # five nearly equal poses
    poses[5:, 7] = np.linspace(1.0, 2.0, 5)    # five far apart
    chosen = spread_frames(list(poses), 3)
    assert chosen == [0, 5, 9]
    assert spread_frames(list(poses[:2]), 5) == [0, 1]


@needs_assets
def test_bone_energy_is_the_mean_length_difference_in_cm():
    from swarmpose.body.loader import load_body

    body = load_body(f"makehuman:{MAKEHUMAN}", "male")
    exact = {(a, b): float(np.linalg.norm(body.point(a) - body.point(b)))
             for a, b in (("left_shoulder", "left_elbow"), ("right_knee", "right_ankle"))}
    assert bone_energy(body, exact) == pytest.approx(0.0, abs=1e-9)
    off = {bone: length + (0.01 if i == 0 else -0.03) for i, (bone, length) in enumerate(exact.items())}
    assert bone_energy(body, off) == pytest.approx(2.0)  # (1 cm + 3 cm) / 2
    assert bone_energy(body, {}) == 0.0


@pytest.fixture(scope="module")
def tall_walk(tmp_path_factory):
    if not MAKEHUMAN.is_dir():
        pytest.skip(f"MakeHuman assets not found at {MAKEHUMAN}")
    from swarmpose.cli.main import main

    out = tmp_path_factory.mktemp("tall")
    assert main(["synth", "--body", f"makehuman:{MAKEHUMAN}", "--shape", "male-tall", "--motion",
                 str(MOCAP / "bvh11_131_01.bvh"), "--frames", "16", "--out", str(out), "--quiet"]) == 0
    return out


@needs_assets
def test_personalize_recovers_a_tall_subjects_height_and_writes_a_body_that_loads(tall_walk, tmp_path, capsys):
    """The start body is 1.68 m; the subject 1.93 m. On this test's small budget (16 frames,
    tracking and pose refits at p = g = 24, 2 rounds) the fit must land within 4 cm of the true
    height and 12 % of the volume (the start body is 25 cm and about 25 % off; the issue's 2 cm /
    5 % goal is measured at the defaults by scripts/bench-personalise.sh), and the GLB must load
    as --body with its parameters."""
    from swarmpose.body.loader import load_body
    from swarmpose.cli.main import main
    from swarmpose.tracking.personalise import body_measures

    glb = tmp_path / "me.glb"
    code = main(["personalize", str(tall_walk), "--body", f"makehuman:{MAKEHUMAN}", "--frames", "16",
                 "--particles", "24", "--generations", "24", "--keyframes", "8", "--rounds", "2",
                 "--out", str(glb), "--json", "--quiet"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    truth = body_measures(load_body(f"makehuman:{MAKEHUMAN}", "male-tall"))
    fitted = load_body(str(glb))
    assert abs(fitted.height - truth["height_m"]) < 0.04, (fitted.height, truth)
    assert report["height_m"] == pytest.approx(fitted.height, abs=1e-3)
    assert abs(report["volume_l"] / truth["volume_l"] - 1) < 0.12, (report["volume_l"], truth)
    assert fitted.metadata["personalised"]["parameters"] == report["parameters"]
    assert set(report["parameters"]) == {"gender", "caucasian", "muscle", "weight", "height"}


@needs_assets
def test_personalize_refuses_a_fixed_body_and_a_recording_without_a_person(tall_walk, tmp_path, capsys):
    from swarmpose.cli.main import main

    assert main(["personalize", str(tall_walk), "--body", str(tmp_path / "x.glb"), "--out",
                 str(tmp_path / "me.glb"), "--quiet"]) == 2
    assert "no shape parameters" in capsys.readouterr().err
    mkv = MAKEHUMAN.parents[1] / "rgbd" / "azure_kinect_one_frame" / "recording.mkv"
    movenet = MAKEHUMAN.parents[1] / "pose2d" / "movenet_singlepose_lightning.onnx"
    assert main(["personalize", f"mkv:{mkv}", "--body", f"makehuman:{MAKEHUMAN}", "--detector", f"onnx:{movenet}",
                 "--frames", "1", "--out", str(tmp_path / "me.glb"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no person was tracked" in err and not (tmp_path / "me.glb").exists()
    assert main(["personalize", str(tall_walk), "--body", f"makehuman:{MAKEHUMAN}", "--out",
                 str(tmp_path / "me.txt"), "--quiet"]) == 2
    assert ".glb" in capsys.readouterr().err


@needs_assets
def test_personalize_n_locks_each_bodys_shape_online_and_status_and_info_say_so(tall_walk):
    """`--personalize 10` on a worker run: statuses go from collecting to locked with the fitted
    parameters (valid against the schemas), the tracker then tracks with the fitted body, and
    the info message carries the same state."""
    from contextlib import ExitStack

    from swarmpose.messages import validate
    from swarmpose.messages.build import info_message
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.service import open_parts
    from swarmpose.pipeline.worker import Worker
    from swarmpose.sources.registry import open_source
    from swarmpose.tracking.config import TrackerConfig

    uri = f"folder:{tall_walk}"
    config = ServiceConfig(source=uri, body=f"makehuman:{MAKEHUMAN}",
                           tracker=TrackerConfig(personalize=10, particles=16, generations=16, max_people=1))
    sink = ValidatingSink()
    with ExitStack() as stack:
        parts = open_parts(config, stack)
        worker = Worker(lambda: open_source(uri), parts.pipeline, [sink], camera="test", drop_stale=False,
                        source_uri=uri, status_period_s=0.1, source=parts.source)
        assert worker.stats.personalisation == {"needed": 10, "bodies": []}  # before any frame
        worker.run()
        states = [(s["tracker"].get("personalisation", {}).get("bodies") or [{}])[0].get("state")
                  for s in sink.statuses]  # before the first frame: personalisation on, no body yet
        assert "collecting" in states and states[-1] == "locked", states
        locked = sink.statuses[-1]["tracker"]["personalisation"]["bodies"][0]
        assert locked["frames"] == locked["needed"] == 10
        assert abs(locked["height_m"] - 1.929) < 0.06, locked  # the start body is 1.68 m
        tracker = parts.pipeline.tracker
        assert tracker.body.height == pytest.approx(locked["height_m"], abs=0.01)  # tracking LOD of the fit
        info = validate(info_message("test", body=tracker.body, body_spec=config.body,
                                     personalisation=parts.pipeline.personalisation))
        assert info["body"]["personalisation"]["bodies"][0]["parameters"] == locked["parameters"]
    assert len(sink.frames) == 16 and all(m["bodies"] for m in sink.frames)


@needs_assets
def test_personalize_n_writes_the_bvh_of_the_locked_body(tall_walk, tmp_path):
    """`--personalize 10 --out DIR`: poses.bvh animates the fitted body, not the start body:
    its offsets are the locked rig's bones and a row written before the lock places the
    joints (read back with the third-party bvhio) where the numpy FK of that frame's pose on the
    locked rig does."""
    from contextlib import ExitStack

    import bvhio

    from swarmpose.body.kinematics import forward_kinematics
    from swarmpose.motion.bvh import read_bvh
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.run import run_sequence
    from swarmpose.pipeline.service import open_parts
    from swarmpose.publish.bvh_file import bvh_transform
    from swarmpose.tracking.config import TrackerConfig

    config = ServiceConfig(source=f"folder:{tall_walk}", body=f"makehuman:{MAKEHUMAN}", overlay=False,
                           tracker=TrackerConfig(personalize=10, particles=16, generations=16, max_people=1))
    with ExitStack() as stack:
        parts = open_parts(config, stack, out=str(tmp_path))
        start = parts.body
        run_sequence(parts.source, parts.pipeline, parts.sinks, frames=12, progress=False)
        locked = parts.pipeline.tracker.body
    assert parts.pipeline.tracker.personalisation()["state"] == "locked"
    assert abs(locked.height - start.height) > 0.05  # a 1.93 m subject, a 1.68 m start body
    clip = read_bvh(tmp_path / "poses.bvh")
    names, parents, heads = locked.bone_names, locked.rig.parents, locked.rig.heads
    assert len(clip) == 12
    for b in range(1, len(names)):
        np.testing.assert_allclose(clip.offsets[clip.joint_index(names[b])], 100.0 * (heads[b] - heads[parents[b]]),
                                   atol=1e-4, err_msg=names[b])
    root = bvhio.readAsHierarchy(str(tmp_path / "poses.bvh"))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    first = json.loads((tmp_path / "poses.jsonl").read_text().splitlines()[0])
    _, expected = forward_kinematics(locked.rig, np.array([first["bodies"][0]["pose"]]))
    to_bvh = bvh_transform(first)
    root.loadPose(0)
    got = np.array([list(joints[n].PositionWorld) for n in names])
    np.testing.assert_allclose(got, 100.0 * (expected[0] @ to_bvh[:3, :3].T + to_bvh[:3, 3]), atol=0.05)


def test_personalize_fits_the_builtin_bodys_height_and_girths(tmp_path, capsys):
    """A built-in male-heavy subject (1.78 m, torso girth 1.35, arms and legs 1.25) from the
    average built-in body (1.75 m, girths 1.0): height within 4 cm and every girth found
    thicker than the start, on a small budget (the oracle: the preset's own numbers)."""
    from swarmpose.body.parametric_shape import BUILTIN_PRESETS
    from swarmpose.cli.main import main

    seq = tmp_path / "heavy"
    assert main(["synth", "--body", "builtin", "--shape", "male-heavy", "--motion", "builtin:walk", "--frames", "12",
                 "--out", str(seq), "--quiet"]) == 0
    capsys.readouterr()  # synth's own lines
    assert main(["personalize", str(seq), "--body", "builtin", "--shape", "male", "--frames", "12", "--particles",
                 "24", "--generations", "24", "--keyframes", "6", "--rounds", "1", "--out", str(tmp_path / "me.glb"),
                 "--json", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    truth = BUILTIN_PRESETS["male-heavy"]
    assert abs(report["height_m"] - truth.height) < 0.04, report
    assert "sex=male" in report["shape"]
    for name in ("torso", "arms", "legs"):
        assert report["parameters"][name] > 1.08, report["parameters"]


def test_personalize_needs_at_least_three_frames():
    from swarmpose.core.errors import ConfigError
    from swarmpose.tracking.config import TrackerConfig

    with pytest.raises(ConfigError, match="at least 3"):
        TrackerConfig(personalize=2)
    assert TrackerConfig(personalize=0).personalize == 0 and TrackerConfig(personalize=3).personalize == 3


@needs_assets
def test_a_failed_fit_is_reported_valid_and_a_new_person_starts_again_from_the_start_body():
    """A fit with too few usable frames fails with its reason (valid in a status message); a
    tracker reused for another person takes the start body back and collects again."""
    from swarmpose.body.makehuman_macros import PRESET_MACROS
    from swarmpose.body.shape_space import MakeHumanSpace
    from swarmpose.core.camera import Intrinsics
    from swarmpose.messages import validate
    from swarmpose.pipeline.status import WorkerStats, status_message
    from swarmpose.tracking.config import TrackerConfig
    from swarmpose.tracking.online_personalise import PersonalisingTracker

    space = MakeHumanSpace(MAKEHUMAN)
    tracker = PersonalisingTracker(space, 3, Intrinsics(320, 240, 280.0, 280.0, 160.0, 120.0),
                                   TrackerConfig(personalize=3, particles=8, generations=8), body_id=4)
    tracker._personalise()  # no samples at all
    state = tracker.personalisation()
    assert state["state"] == "failed" and "0 of 0 frames" in state["reason"] and state["id"] == 4
    stats = WorkerStats()
    stats.update(personalisation={"needed": 3, "bodies": [state]})
    validate(status_message("t", "running", stats, 1.0, 1.0, source_uri="x", source_state="running",
                            detector_spec="simulated", zenoh=None, opencl_device="", errors=[]))

    heavy = space.tracking_body(PRESET_MACROS["male-heavy"].vector())
    tracker.set_body(heavy)
    tracker.state = "locked"
    tracker.new_person()
    assert tracker.personalisation() == {"id": 4, "state": "collecting", "frames": 0, "needed": 3}
    np.testing.assert_allclose(tracker.body.vertices, space.tracking_body(space.start).vertices)
    np.testing.assert_allclose(tracker.objective.scorer.body.vertices, tracker.body.vertices)
