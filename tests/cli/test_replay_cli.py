"""`swarmpose replay` end to end (files, Δ from an independent computation, damaged input) and
`swarmpose serve` with examples/subscribe.py beside it, as a new user runs them."""

from __future__ import annotations

import csv
import json
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pytest
from conftest import REPO, free_port

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.cli.main import main
from swarmpose.core.polling import wait_until
from swarmpose.motion.bvh import read_bvh
from swarmpose.sources.groundtruth import load_ground_truth

FAST = ["--particles", "12", "--generations", "8", "--quiet"]
BIN = Path(sys.executable).parent


@pytest.mark.slow
def test_replay_writes_every_output_and_scores_it(wave_sequence, tmp_path, capsys):
    out = tmp_path / "replay"
    assert main(["replay", "--source", str(wave_sequence), "--out", str(out), "--json"] + FAST) == 0
    result = json.loads(capsys.readouterr().out)
    messages = [json.loads(x) for x in (out / "poses.jsonl").read_text().splitlines()]
    assert [m["frame"] for m in messages] == list(range(6)) and result["frames"] == 6
    truth = load_ground_truth(wave_sequence).joints3d
    est = np.array([[m["bodies"][0]["joints"][j]["position_m"] for j in EVAL_JOINTS] for m in messages], float)
    assert abs(result["mpjpe_mm"] - 1000 * np.linalg.norm(est - truth, axis=2).mean()) <= 0.05   # printed to 0.1
    assert result["mpjpe_mm"] < 80 and result["A"]["100"] > 0.8 and result["fps"] > 0
    rows = list(csv.DictReader((out / "poses.csv").open()))
    assert [int(r["frame"]) for r in rows] == list(range(6))
    assert float(rows[2]["head_z"]) == messages[2]["bodies"][0]["joints"]["head"]["position_m"][2]
    assert len(read_bvh(out / "poses.bvh")) == 6
    with av.open(str(out / "overlay.mp4")) as video:
        assert sum(1 for _ in video.decode(video=0)) == 6
    assert set(result["outputs"]) == {str(out / n) for n in ("poses.jsonl", "poses.csv", "poses.bvh", "overlay.mp4",
                                                             "poses_ros2/poses_ros2.mcap", "poses_ros2/metadata.yaml")}


def test_replay_of_a_damaged_recording_reports_and_goes_on(wave_sequence, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(wave_sequence, broken)
    (broken / "depth" / "000002.png").write_bytes(b"\x89PNG truncated")
    out = tmp_path / "out"
    assert main(["replay", "--source", f"folder:{broken}", "--out", str(out), "--mode", "lift", "--json",
                 "--no-overlay", "--quiet"]) == 0
    result = json.loads(capsys.readouterr().out)
    messages = [json.loads(x) for x in (out / "poses.jsonl").read_text().splitlines()]
    assert [m["frame"] for m in messages] == list(range(6))
    assert messages[2]["bodies"] == [] and "000002.png" in messages[2]["reason"]
    assert result["skipped"] == 1 and result["coverage"] < 1.0 and not (out / "overlay.mp4").exists()


@pytest.mark.slow
def test_replay_bad_input_exits_2_naming_it(wave_sequence, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["replay", "--source", str(wave_sequence), "--out", str(blocker / "out"), "--quiet"]) == 2
    assert str(blocker) in capsys.readouterr().err
    assert main(["replay", "--source", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert main(["replay", "--source", str(wave_sequence), "--out", str(tmp_path / "o"), "--joints", "onnx:/no.onnx",
                 "--quiet"]) == 2
    assert "/no.onnx" in capsys.readouterr().err
    run = subprocess.run([str(BIN / "swarmpose"), "replay", "--source", str(wave_sequence)], capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 2 and "--out" in run.stderr


@pytest.mark.slow
def test_serve_with_the_example_subscriber_beside_it(wave_sequence, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    health = tmp_path / "status.json"
    serve = subprocess.Popen([str(BIN / "swarmpose"), "serve", "--source", f"folder:{wave_sequence}",
                              "--camera-id", "kinect0", "--listen", endpoint, "--no-multicast", "--mode", "lift",
                              "--rate", "5", "--loop", "--health-file", str(health), "--status-period", "0.3"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        published = wait_until(lambda: serve.poll() is not None or (
            health.exists() and json.loads(health.read_text())["frames"]["published"] > 0), timeout=60, step=0.2)
        assert published and serve.poll() is None, "the worker did not start"
        sub = subprocess.run([sys.executable, str(REPO / "examples" / "subscribe.py"), "--connect", endpoint,
                              "--no-multicast", "--count", "4"], capture_output=True, text=True, timeout=120)
        assert sub.returncode == 0, sub.stderr
        lines = sub.stdout.splitlines()
        assert any(x.startswith(f"worker kinect0: folder:{wave_sequence} (640x480), body builtin") for x in lines)
        frames = [x for x in lines if x.startswith("kinect0 frame")]
        # each pass over the loop starts its track afresh, under a new id (ids are never reused)
        assert len(frames) == 4 and all(re.search(r"body \d+ tracking head \(", x) for x in frames)
    finally:
        serve.terminate()
        assert serve.wait(timeout=30) == 0
    assert "swarmpose serve: folder:" in serve.stderr.read()


def test_replay_with_an_output_that_fails_every_frame_reports_it_once_and_exits_1(wave_sequence, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "poses.jsonl").symlink_to("/dev/full")        # every write: no space left on device
    assert main(["replay", str(wave_sequence), "--out", str(out), "--mode", "lift", "--no-overlay", "--json",
                 "--quiet"]) == 1
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert len(result["sink_errors"]) == 1 and "No space left on device" in result["sink_errors"][0]
    assert captured.err.count("No space left on device") == 1 and "it gets no more messages" in captured.err
    assert [int(r["frame"]) for r in csv.DictReader((out / "poses.csv").open())] == list(range(6))  # the others go on
    assert len(read_bvh(out / "poses.bvh")) == 6


@pytest.mark.slow
def test_replay_stopped_by_a_signal_exits_130_keeping_what_it_tracked(wave_sequence, tmp_path):
    out = tmp_path / "out"
    replay = subprocess.Popen([str(BIN / "swarmpose"), "replay", str(wave_sequence), "--out", str(out), "--mode",
                               "lift", "--rate", "2", "--no-overlay", "--quiet"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wrote = wait_until(lambda: replay.poll() is not None or (
            (out / "poses.jsonl").exists() and (out / "poses.jsonl").read_text()), timeout=60)
        assert wrote and replay.poll() is None, "replay did not start"
        replay.send_signal(signal.SIGINT)
        assert replay.wait(timeout=30) == 130
    finally:
        if replay.poll() is None:
            replay.kill()
    assert "interrupted" in replay.stderr.read()
    frames = [json.loads(x)["frame"] for x in (out / "poses.jsonl").read_text().splitlines()]
    assert 1 <= len(frames) < 6 and frames == list(range(len(frames)))


@pytest.mark.slow
def test_replay_offers_no_flags_it_would_ignore(wave_sequence, tmp_path, capsys):
    for flag in (["--loop"], ["--record", str(tmp_path / "r")]):
        with pytest.raises(SystemExit) as exit_:
            main(["replay", str(wave_sequence), "--out", str(tmp_path / "o")] + flag)
        assert exit_.value.code == 2 and f"unrecognized arguments: {flag[0]}" in capsys.readouterr().err
    help_text = subprocess.run([str(BIN / "swarmpose"), "serve", "--help-all"], capture_output=True, text=True,
                               timeout=60).stdout
    assert "--loop" in help_text and "--record" in help_text        # serve keeps them (--loop: advanced)
