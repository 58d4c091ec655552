"""The public Python API (``swarmpose.Tracker``, ``swarmpose.track``) and the example program:
checked against the sequence's ground truth, against the command line (one pipeline for
both), and on bad input."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import swarmpose
from swarmpose.body.joint_set import SKELETON_NAMES
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError, ShapeError, SourceError
from swarmpose.messages import validate
from swarmpose.sources.base import FrameSource
from swarmpose.sources.groundtruth import load_ground_truth

REPO = Path(__file__).resolve().parents[2]
FAST = {"particles": 16, "generations": 12}


@pytest.mark.slow
def test_the_example_program_tracks_a_synthetic_sequence(wave_sequence):
    run = subprocess.run([sys.executable, str(REPO / "examples" / "track_my_camera.py"), str(wave_sequence),
                          "--frames", "4", "--particles", "16", "--generations", "12", "--json"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    messages = [validate(json.loads(line)) for line in run.stdout.splitlines()]
    assert [m["frame"] for m in messages] == [0, 1, 2, 3] and all(m["camera"] == "kinect0" for m in messages)
    gt = load_ground_truth(wave_sequence)
    names = list(messages[0]["bodies"][0]["joints"])
    est = np.array([[m["bodies"][0]["joints"][n]["position_m"] for n in names] for m in messages])
    assert 1000 * np.linalg.norm(est - gt.joints3d[:4], axis=2).mean() < 80


@pytest.mark.slow
def test_track_gives_what_the_command_line_writes(wave_sequence, tmp_path):
    """swarmpose.track and `swarmpose track` run the same per-frame step: same poses, same messages."""
    api = list(swarmpose.track(f"folder:{wave_sequence}", detector="simulated", frames=4, **FAST))
    assert [r.index for r in api] == [0, 1, 2, 3] and [r.state for r in api] == ["init"] + ["tracking"] * 3
    assert main(["track", str(wave_sequence), "--out", str(tmp_path), "--frames", "4", "--particles", "16",
                 "--generations", "12", "--no-overlay", "-q"]) == 0
    cli = [json.loads(line) for line in (tmp_path / "poses.jsonl").read_text().splitlines()]
    for result, message in zip(api, cli):
        ours = result.to_message("camera0")
        assert ours["bodies"] == message["bodies"]
        body = result.bodies[0]
        assert np.allclose(body.pose, message["bodies"][0]["pose"], atol=1e-6)
        wrist = body.joints["left_wrist"]
        assert np.allclose(wrist.position_m, message["bodies"][0]["joints"]["left_wrist"]["position_m"], atol=1e-6)
        assert 0.0 <= wrist.confidence <= 1.0 and wrist.pixel.shape == (2,)
        # the full set: the tracker's skeleton is its pose's (the 14 where joints3d are, the pelvis at tx ty tz)
        assert len(body.joints) == 28 and body.joints["pelvis"].position_m == pytest.approx(body.pose[:3])
        np.testing.assert_allclose(np.stack([body.joints[n].position_m for n in EVAL_JOINTS]),
                                   body.skeleton.positions[[SKELETON_NAMES.index(n) for n in EVAL_JOINTS]], atol=1e-9)
        assert all(abs(np.linalg.norm(j.orientation_xyzw) - 1) < 1e-9 for j in body.joints.values())


@pytest.mark.slow
def test_tracker_on_arrays_follows_the_ground_truth(wave_sequence):
    source = swarmpose.open_source(f"folder:{wave_sequence}")
    frames = [f for f in source if isinstance(f, swarmpose.Frame)]
    body = swarmpose.load_body("builtin")
    with swarmpose.Tracker(body=body, detector="simulated", intrinsics=frames[0].intrinsics, source=source,
                           **FAST) as tracker:
        results = [tracker.track(f.depth, f.color, timestamp_ns=f.timestamp_ns) for f in frames[:4]]
    source.close()
    assert [r.index for r in results] == [0, 1, 2, 3]
    gt = load_ground_truth(wave_sequence)
    est = np.array([r.bodies[0].joints3d for r in results])
    assert 1000 * np.linalg.norm(est - gt.joints3d[:4], axis=2).mean() < 80
    with pytest.raises(ConfigError, match="closed"):
        tracker.track(frames[0].depth)


def test_bad_input_is_named(wave_sequence):
    K = swarmpose.Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    with pytest.raises(ConfigError, match="unknown setting"):
        swarmpose.Tracker(detector="simulated", particels=3)
    with pytest.raises(ConfigError, match="particles must be at least 1"):
        swarmpose.Tracker(particles=0)
    source = swarmpose.open_source(f"folder:{wave_sequence}")
    with swarmpose.Tracker(detector="simulated", source=source, mode="lift") as tracker:
        with pytest.raises(ConfigError, match="intrinsics"):
            tracker.track(np.zeros((480, 640), np.float32))
    with swarmpose.Tracker(detector="simulated", source=source, intrinsics=K, mode="lift") as tracker:
        with pytest.raises(ShapeError, match="depth_m has shape"):
            tracker.track(np.zeros((48, 64), np.float32))
        with pytest.raises(ShapeError, match="rgb"):
            tracker.track(np.zeros((480, 640), np.float32), np.zeros((480, 640), np.uint8))
        empty = tracker.track(np.zeros((480, 640), np.float32))  # several-people mode: nobody, and why
        assert empty.bodies == () and "no person" in empty.reason
    with swarmpose.Tracker(detector="simulated", source=source, intrinsics=K, mode="lift", max_people=1) as tracker:
        empty = tracker.track(np.zeros((480, 640), np.float32))  # one person: a body that is lost, and why
        assert empty.bodies[0].state == "lost" and empty.bodies[0].reason
    source.close()


def test_import_is_light_and_the_package_logs_nowhere_by_default():
    code = ("import sys, logging, swarmpose; heavy = [m for m in ('open3d', 'pyopencl', 'onnxruntime', 'zenoh') "
            "if m in sys.modules]; print(heavy, logging.getLogger('swarmpose').handlers)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.startswith("[] [<NullHandler")
    assert sorted(swarmpose.__all__) == swarmpose.__all__ and "Tracker" in dir(swarmpose)


@pytest.mark.slow
def test_subscribe_has_normal_flags_and_help():
    run = subprocess.run([sys.executable, "-m", "swarmpose", "subscribe", "--help"], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0 and "--count" in run.stdout and "--connect" in run.stdout
    run = subprocess.run([sys.executable, "-m", "swarmpose", "subscribe", "--count", "1", "--timeout", "0.5",
                          "--no-multicast", "--connect", "tcp/127.0.0.1:1"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and "got 0 of 1 frames" in run.stderr


def test_settings_by_name_are_converted_and_checked_as_flags_are(wave_sequence):
    with pytest.raises(ConfigError, match="argument particles: particles = 'many' is not an integer"):
        swarmpose.Tracker(particles="many")
    with pytest.raises(ConfigError, match="particles = 6.5 is not an integer"):
        swarmpose.Tracker(particles=6.5)
    with pytest.raises(ConfigError, match="threshold_m must be a finite number; got nan"):
        swarmpose.Tracker(threshold_m=float("nan"))
    with pytest.raises(ConfigError, match="pso must be one of"):
        swarmpose.Tracker(pso=3)
    with pytest.raises(ConfigError, match="tile sides must be within 8..512 pixels; got 4x4"):
        swarmpose.Tracker(tile=(4, 4))
    with pytest.raises(ConfigError, match="tile sides must be within 8..512 pixels; got 1024x64"):
        swarmpose.TrackerConfig(tile=(1024, 64))
    with pytest.raises(ConfigError, match="tile must be WxH pixels"):
        swarmpose.TrackerConfig(tile=(64.5, 64))
    source = swarmpose.open_source(f"folder:{wave_sequence}")
    with swarmpose.Tracker(source=source, particles="32", tile="32x48", smoothing="one-euro") as tracker:
        assert (tracker.config.particles, tracker.config.tile, tracker.config.smoothing) == (32, (32, 48), "one-euro")
    source.close()


def test_the_simulated_detector_without_a_source_says_what_to_pass():
    with pytest.raises(ConfigError, match=r"simulated detector .*swarmpose synth.* source=.*detector='onnx:movenet"):
        swarmpose.Tracker(detector="simulated")


class CountingSource(FrameSource):
    """The real folder source, counting the items read from it; its device 'vanishes' after ``keep``."""

    def __init__(self, inner, keep=None):
        self.inner, self.keep, self.uri, self.length, self.reads = inner, keep, inner.uri, inner.length, 0
        self.ground_truth = inner.ground_truth

    def _frames(self):
        for i, item in enumerate(self.inner):
            if i == self.keep:
                raise SourceError("USB device disconnected")
            self.reads += 1
            yield item


def test_track_reads_no_frame_past_frames_and_warns_when_the_source_breaks(wave_sequence, caplog):
    source = CountingSource(swarmpose.open_source(f"folder:{wave_sequence}"))
    assert [r.index for r in swarmpose.track(source, frames=2, mode="lift")] == [0, 1]
    assert source.reads == 2
    dying = CountingSource(swarmpose.open_source(f"folder:{wave_sequence}"), keep=3)
    with caplog.at_level(logging.WARNING, logger="swarmpose"):
        assert [r.index for r in swarmpose.track(dying, mode="lift")] == [0, 1, 2]
    assert dying.status == "error: USB device disconnected"
    assert any(f"source folder:{wave_sequence} ended with an error: USB device disconnected" in r.getMessage()
               for r in caplog.records)


@pytest.mark.slow
@pytest.mark.parametrize("settings, flags", [
    ({"coordinates": "world", **FAST}, ["--coordinates", "world", "--particles", "16", "--generations", "12"]),
    ({"personalize": 3, **FAST}, ["--personalize", "3", "--particles", "16", "--generations", "12"]),
], ids=["world", "personalize"])
def test_the_api_has_the_world_frame_and_personalisation_of_the_command_line(wave_sequence, tmp_path, settings,
                                                                               flags):
    """One pipeline builder for both: the same messages, in the world frame or with the body fitted online."""
    api = [r.to_message("camera0") for r in swarmpose.track(f"folder:{wave_sequence}", detector="simulated",
                                                             frames=5, **settings)]
    assert main(["track", str(wave_sequence), "--out", str(tmp_path), "--frames", "5", "--no-overlay", "-q",
                 *flags]) == 0
    cli = [json.loads(line) for line in (tmp_path / "poses.jsonl").read_text().splitlines()]
    assert [m["bodies"] for m in api] == [m["bodies"] for m in cli]
    assert [m["coordinates"] for m in api] == [m["coordinates"] for m in cli]
    if "coordinates" in settings:  # y up, the floor at y = 0: the ankles are near it
        assert all(m["coordinates"] == "world" for m in api)
        ankles = [m["bodies"][0]["joints"][n]["position_m"][1] for m in api for n in ("left_ankle", "right_ankle")]
        assert 0.0 < np.median(ankles) < 0.2


def test_personalize_needs_a_body_given_by_name():
    with pytest.raises(ConfigError, match="give the body by name"):
        swarmpose.Tracker(body=swarmpose.load_body("builtin"), personalize=3)
