"""Command-line behaviour: bad input gives one clear line and exit status 2, no traceback."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest
from conftest import MAKEHUMAN, MOCAP, needs_assets

from swarmpose.cli.main import main


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmpose", *args], capture_output=True, text=True, timeout=300)


def _assert_clean_error(proc: subprocess.CompletedProcess, *words: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    for word in words:
        assert word in last, last


@pytest.mark.slow
def test_unknown_builtin_preset(tmp_path):
    proc = _run("synth", "--shape", "giant", "--motion", "builtin:wave", "--frames", "1", "--out", str(tmp_path))
    _assert_clean_error(proc, "giant", "default")


@pytest.mark.slow
def test_unknown_builtin_motion(tmp_path):
    proc = _run("synth", "--motion", "builtin:moonwalk", "--frames", "1", "--out", str(tmp_path))
    _assert_clean_error(proc, "moonwalk", "wave")


@pytest.mark.slow
def test_missing_makehuman_directory(tmp_path):
    proc = _run("synth", "--body", f"makehuman:{tmp_path / 'nowhere'}", "--motion", "builtin:wave", "--frames", "1",
                "--out", str(tmp_path / "out"))
    _assert_clean_error(proc, "nowhere", "base.obj")


@pytest.mark.slow
def test_missing_and_foreign_bvh(tmp_path):
    _assert_clean_error(_run("synth", "--motion", str(tmp_path / "none.bvh"), "--frames", "1", "--out", str(tmp_path)),
                        "none.bvh")
    robot = tmp_path / "robot.bvh"
    robot.write_text("HIERARCHY\nROOT Base\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
                     " End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n")
    _assert_clean_error(_run("synth", "--motion", str(robot), "--frames", "1", "--out", str(tmp_path / "o")),
                        "unknown BVH skeleton")


@pytest.mark.slow
def test_unwritable_output(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    proc = _run("synth", "--motion", "builtin:wave", "--frames", "1", "--out", str(blocker / "seq"))
    _assert_clean_error(proc, str(blocker / "seq"), "--out")


@pytest.mark.slow
def test_bad_flags_exit_2():
    assert _run("synth", "--motion", "builtin:wave", "--frames", "0", "--out", "x").returncode == 2
    assert _run("synth", "--frames", "3", "--out", "x").returncode == 2  # --motion missing
    _assert_clean_error(_run("synth", "--motion", "builtin:wave", "--frames", "1", "--out", "x",
                             "--camera-distance", "50"), "--camera-distance")


@pytest.mark.slow
@needs_assets
def test_out_of_range_numbers_are_clean_errors(tmp_path):
    base = ("synth", "--motion", "builtin:wave", "--frames", "1", "--out", str(tmp_path / "x"))
    _assert_clean_error(_run(*base, "--seed", "-1"), "--seed")
    _assert_clean_error(_run(*base, "--camera-height", "nan"), "--camera-height")
    _assert_clean_error(_run(*base, "--fps", "0"), "--fps")
    _assert_clean_error(_run("body", "--lod", "4"), "at least 100")
    assert not (tmp_path / "x" / "groundtruth.jsonl").exists()


@pytest.mark.slow
@needs_assets
def test_more_frames_than_the_clip_has(tmp_path):
    proc = _run("synth", "--motion", str(MOCAP / "makehuman_walk1.bvh"), "--frames", "500", "--out", str(tmp_path))
    _assert_clean_error(proc, "--frames")


def test_body_info_json(capsys):
    assert main(["body", "--body", "builtin", "--shape", "female", "--lod", "1500", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert 1300 <= info["triangles"] <= 1700 and 1.6 < info["height_m"] < 1.7


@needs_assets
def test_makehuman_preset_exported_to_glb_reloads(tmp_path, capsys):
    glb = tmp_path / "male-heavy.glb"
    assert main(["body", "--body", f"makehuman:{MAKEHUMAN}", "--shape", "male-heavy", "--export", str(glb)]) == 0
    capsys.readouterr()
    assert main(["body", "--body", str(glb), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["vertices"] == 13380 and abs(info["height_m"] - 1.748) < 0.01


@pytest.mark.slow
def test_demo_writes_a_sequence_and_tracks_it(tmp_path, capsys):
    args = ["demo", "--out", str(tmp_path / "demo"), "--frames", "3", "--particles", "12", "--generations", "8"]
    assert main(args + ["--quiet"]) == 0
    out = capsys.readouterr().out
    assert "wrote 3 frames" in out and (tmp_path / "demo" / "depth" / "000002.png").is_file()
    assert "Δ = " in out and "A(t):" in out and "frames/s; latency median" in out
    received = [line for line in out.splitlines() if line.startswith("  subscriber | demo frame")]
    assert len(received) == 3 and "the subscriber received 3 frames (exit status 0)" in out
    messages = [json.loads(line) for line in (tmp_path / "replay" / "poses.jsonl").read_text().splitlines()]
    assert [m["frame"] for m in messages] == [0, 1, 2]
    for name in ("poses.csv", "poses.bvh", "overlay.mp4"):
        assert (tmp_path / "replay" / name).stat().st_size > 0


@pytest.mark.slow
def test_demo_with_a_replay_file_that_cannot_be_written_exits_1_keeping_the_rest(tmp_path, capsys):
    replay = tmp_path / "replay"
    replay.mkdir()
    (replay / "poses.jsonl").symlink_to("/dev/full")      # every write: no space left on device
    args = ["demo", "--out", str(tmp_path / "demo"), "--frames", "3", "--particles", "12", "--generations", "8"]
    assert main(args + ["--quiet"]) == 1
    captured = capsys.readouterr()
    assert "the subscriber received 3 frames (exit status 0)" in captured.out
    assert "failed (nothing more written to it): JsonlSink: cannot write" in captured.out
    assert captured.err.count("No space left on device") == 1
    assert [int(r["frame"]) for r in csv.DictReader((replay / "poses.csv").open())] == [0, 1, 2]


@pytest.mark.slow
def test_bench_score_json_has_the_documented_keys(capsys):
    assert main(["bench", "score", "--particles", "4", "--resolution", "16x16", "--repeats", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("hypotheses_per_s", "baseline_hypotheses_per_s", "ratio", "particles", "resolution", "triangles",
                "device"):
        assert key in result
    assert result["particles"] == 4 and result["resolution"] == [16, 16] and result["max_sum_difference"] < 1e-4
    assert _run("bench", "score", "--resolution", "64by64").returncode == 2


@pytest.mark.slow
def test_bench_name_lists_default_to_the_values_their_help_shows():
    """The comma-separated bench options parse their defaults as a typed value would (a tuple of
    names), and their help shows the names as one would type them, not a tuple's repr."""
    from swarmpose.cli.main import build_parser

    parser = build_parser()
    utd = parser.parse_args(["bench", "utdmhad", "--out", "x"])
    assert (utd.modes, utd.detectors, utd.shapes, utd.subjects) == (("hybrid",), ("simulated",), ("default",),
                                                                     ("s1", "s2", "s3"))
    assert utd.modes == parser.parse_args(["bench", "utdmhad", "--out", "x", "--modes", "hybrid"]).modes
    accuracy = parser.parse_args(["bench", "accuracy", "--out", "x"])
    assert accuracy.modes == ("hybrid", "joints", "depth", "lift")
    text = subprocess.run([sys.executable, "-m", "swarmpose", "bench", "utdmhad", "--help"], capture_output=True,
                          text=True, check=True).stdout
    assert "(default: hybrid)" in " ".join(text.split()) and "('hybrid'" not in text
