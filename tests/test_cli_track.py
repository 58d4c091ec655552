"""`swarmpose track` / `swarmpose eval` end to end on a synthetic sequence, and their bad input:
a corrupt PNG, a missing frame, a folder without ground truth, a run cut short."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from swarmpose.cli import main
from swarmpose.errors import SourceError
from swarmpose.groundtruth import load_ground_truth
from swarmpose.model.loader import load_body
from swarmpose.sources.registry import open_source
from swarmpose.track_run import track_source
from swarmpose.tracker import Tracker, TrackerConfig

FAST = ["--particles", "16", "--generations", "12", "--quiet"]


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("seq")
    assert main(["synth", "--motion", "builtin:wave", "--frames", "5", "--out", str(out), "--quiet"]) == 0
    return out


def test_track_writes_one_line_per_frame(sequence, tmp_path, capsys):
    out = tmp_path / "poses.jsonl"
    assert main(["track", str(sequence), "--out", str(out)] + FAST) == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert [x["frame"] for x in lines] == list(range(5))
    assert lines[0]["state"] == "init" and all(x["state"] == "tracking" for x in lines[1:])
    assert set(lines[0]["joints3d"]) >= {"head", "left_wrist", "right_ankle"} and len(lines[0]["pose"]) == 36
    assert lines[0]["detections"]["layout"] == "coco17"
    assert "tracked 5 frames" in capsys.readouterr().out


def test_eval_json_matches_an_independent_error(sequence, tmp_path, capsys):
    out = tmp_path / "poses.jsonl"
    plot = tmp_path / "a.png"
    assert main(["eval", str(sequence), "--json", "--out", str(out), "--plot", str(plot)] + FAST) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("mpjpe_mm", "A", "fps", "frames", "mode"):
        assert key in result
    assert result["frames"] == 5 and result["mode"] == "hybrid" and set(result["A"]) == {str(t) for t in
                                                                                          range(20, 201, 20)}
    gt = load_ground_truth(sequence)
    est = np.array([[p for p in json.loads(x)["joints3d"].values()] for x in out.read_text().splitlines()])
    delta = 1000 * np.linalg.norm(est - gt.joints3d, axis=2).mean()
    assert result["mpjpe_mm"] == pytest.approx(delta, rel=1e-4)
    assert result["mpjpe_mm"] < 80
    assert plot.stat().st_size > 1000


def test_damaged_sequence_is_reported_and_tracking_goes_on(sequence, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(sequence, broken)
    (broken / "depth" / "000001.png").write_bytes(b"\x89PNG not really")
    (broken / "color" / "000003.png").unlink()
    out = tmp_path / "poses.jsonl"
    assert main(["track", str(broken), "--out", str(out)] + FAST) == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    states = {x["frame"]: x["state"] for x in lines}
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
    assert main(["track", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x.jsonl")]) == 2
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

    from swarmpose.joints2d.registry import make_detector

    out = tmp_path / "poses.jsonl"
    body = load_body("builtin")
    config = TrackerConfig(mode="lift")
    with pytest.raises(SourceError):
        track_source(dying(), make_detector("simulated", source), lambda intr: Tracker(body, intr, config), out=out,
                     progress=False)
    assert [json.loads(x)["frame"] for x in out.read_text().splitlines()] == [0, 1]
