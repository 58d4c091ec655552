"""`swarmpose track` / `swarmpose eval` end to end on a synthetic sequence, and their bad input:
a corrupt PNG, a missing frame, a folder without ground truth, a run cut short, a source that
breaks off."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.cli.main import main
from swarmpose.core.errors import SourceError
from swarmpose.detect.registry import make_detector
from swarmpose.messages import validate
from swarmpose.pipeline.run import run_sequence
from swarmpose.pipeline.step import FramePipeline
from swarmpose.publish.files import JsonlSink
from swarmpose.sources.base import FrameSource
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

FAST = ["--particles", "16", "--generations", "12", "--quiet", "--no-overlay"]


def state(message: dict) -> str:
    """The frame's state as the old per-frame records had it: skipped, the body's, or lost."""
    if message["reason"].startswith("skipped"):
        return "skipped"
    return message["bodies"][0]["state"] if message["bodies"] else "lost"


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("seq")
    assert main(["synth", "--motion", "builtin:wave", "--frames", "5", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.slow
def test_track_writes_one_line_per_frame(sequence, tmp_path, capsys):
    assert main(["track", str(sequence), "--out", str(tmp_path)] + FAST) == 0
    lines = [validate(json.loads(x)) for x in (tmp_path / "poses.jsonl").read_text().splitlines()]
    assert [x["frame"] for x in lines] == list(range(5))
    assert state(lines[0]) == "init" and all(state(x) == "tracking" for x in lines[1:])
    body = lines[0]["bodies"][0]
    assert set(body["joints"]) >= {"head", "left_wrist", "right_ankle"} and len(body["pose"]) == 36
    assert body["detection"]["layout"] == "coco17"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.bvh", "poses.csv", "poses.jsonl", "poses_ros2",
                                                             "run.json"]
    assert "tracked 5 frames" in capsys.readouterr().out


@pytest.mark.slow
def test_eval_json_matches_an_independent_error(sequence, tmp_path, capsys):
    out = tmp_path / "poses.jsonl"
    plot = tmp_path / "a.png"
    assert main(["eval", str(sequence), "--json", "--out", str(tmp_path), "--plot", str(plot)] + FAST) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("mpjpe_mm", "A", "fps", "frames", "mode"):
        assert key in result
    assert result["frames"] == 5 and result["mode"] == "hybrid" and set(result["A"]) == {str(t) for t in
                                                                                          range(20, 201, 20)}
    gt = load_ground_truth(sequence)
    est = np.array([[json.loads(x)["bodies"][0]["joints"][n]["position_m"] for n in EVAL_JOINTS]
                    for x in out.read_text().splitlines()])
    delta = 1000 * np.linalg.norm(est - gt.joints3d, axis=2).mean()
    assert result["mpjpe_mm"] == pytest.approx(delta, rel=1e-4)
    assert result["mpjpe_mm"] < 80
    assert plot.stat().st_size > 1000


@pytest.mark.slow
def test_damaged_sequence_is_reported_and_tracking_goes_on(sequence, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(sequence, broken)
    (broken / "depth" / "000001.png").write_bytes(b"\x89PNG not really")
    (broken / "color" / "000003.png").unlink()
    assert main(["track", str(broken), "--out", str(tmp_path / "out")] + FAST) == 0
    lines = [json.loads(x) for x in (tmp_path / "out" / "poses.jsonl").read_text().splitlines()]
    states = {x["frame"]: state(x) for x in lines}
    assert states[1] == "skipped" and states[3] == "skipped"
    assert "000001.png" in next(x["reason"] for x in lines if x["frame"] == 1)
    assert states[0] == "init" and states[2] == "tracking" and states[4] == "tracking"


def test_eval_needs_ground_truth_and_bad_flags_exit_2(sequence, tmp_path, capsys):
    bare = tmp_path / "bare"
    shutil.copytree(sequence, bare)
    (bare / "groundtruth.jsonl").unlink()
    assert main(["eval", str(bare), "--mode", "lift", "--joints", "onnx:/nonexistent.onnx", "--quiet"]) == 2
    assert "nonexistent.onnx" in capsys.readouterr().err
    assert main(["eval", str(bare), "--mode", "lift", "--quiet"]) == 2
    assert "groundtruth" in capsys.readouterr().err
    assert main(["track", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x")]) == 2
    assert main(["track", str(sequence), "--source", str(bare), "--out", str(tmp_path / "x")]) == 2
    assert "two sources" in capsys.readouterr().err
    assert main(["eval", str(sequence), "--depth-weight", "-1", "--quiet"]) == 2
    with pytest.raises(SystemExit):
        main(["eval", str(sequence), "--mode", "nonsense"])


def test_lines_written_before_a_failure_are_kept(sequence, tmp_path):
    """A source that dies mid-run: every line already written is on disk."""
    source = open_source(f"folder:{sequence}")

    def dying():
        for i, frame in enumerate(source):
            if i == 2:
                raise SourceError("camera unplugged")
            yield frame

    out = tmp_path / "poses.jsonl"
    body = load_body("builtin")
    config = TrackerConfig(mode="lift")
    pipeline = FramePipeline(make_detector("simulated", source), lambda intr, _id: BodyTracker(body, intr, config),
                             max_people=1)
    with pytest.raises(SourceError):
        run_sequence(dying(), pipeline, [JsonlSink(out)], progress=False)
    lines = [validate(json.loads(x)) for x in out.read_text().splitlines()]
    assert [x["frame"] for x in lines] == [0, 1]


class VanishingSource(FrameSource):
    """The real folder source, whose device 'vanishes' after ``keep`` frames."""

    def __init__(self, inner, keep):
        self.inner, self.keep, self.uri, self.length = inner, keep, inner.uri, inner.length
        self.ground_truth = inner.ground_truth

    def _frames(self):
        for i, item in enumerate(self.inner):
            if i == self.keep:
                raise SourceError("USB device disconnected")
            yield item

    def close(self):
        self.inner.close()


@pytest.mark.parametrize("command", ["track", "eval"])
def test_a_source_that_breaks_off_is_named_and_exits_1_keeping_the_frames(sequence, tmp_path, capsys, monkeypatch,
                                                                           command):
    monkeypatch.setattr("swarmpose.pipeline.service.open_source", lambda uri: VanishingSource(open_source(uri), 3))
    out = tmp_path / "out"
    assert main([command, str(sequence), "--out", str(out), "--mode", "lift"] + FAST) == 1
    lines = [json.loads(x) for x in (out / "poses.jsonl").read_text().splitlines()]
    assert [x["frame"] for x in lines] == [0, 1, 2]
    err = capsys.readouterr().err
    assert f"source {sequence} ended with an error: USB device disconnected" in err


def test_eval_without_ground_truth_fails_before_tracking(sequence, tmp_path, capsys):
    bare = tmp_path / "bare"
    shutil.copytree(sequence, bare)
    (bare / "groundtruth.jsonl").unlink()
    detections = tmp_path / "openpose"
    detections.mkdir()
    (detections / "v_000000000000_keypoints.json").write_text(json.dumps({"people": []}))
    out = tmp_path / "out"
    assert main(["eval", str(bare), "--detector", f"openpose-json:{detections}", "--mode", "lift", "--out", str(out),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{bare} has no ground truth" in err and "`swarmpose synth`" in err and "`swarmpose track`" in err
    assert not (out / "poses.jsonl").exists()     # it failed before tracking a frame
