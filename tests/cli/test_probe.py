"""`swarmpose probe`: per-frame facts of a source, checked against the files' own pixels and the
detections `swarmpose synth` recorded."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, needs_assets

from swarmpose.cli.main import main


@pytest.fixture(scope="module")
def seq(tmp_path_factory) -> Path:
    from swarmpose.body.loader import load_body
    from swarmpose.motion.builtin import builtin_motion
    from swarmpose.sim.synth import SynthConfig, synthesize

    out = tmp_path_factory.mktemp("probe") / "seq"
    synthesize(load_body("builtin").tracking_lod(1500), builtin_motion("wave", 3, 30.0), out,
               SynthConfig(frames=3, seed=2), progress=False)
    return out


def _json_lines(capsys) -> tuple[list[dict], dict]:
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    return lines[:-1], lines[-1]["summary"]


def test_json_records_match_the_depth_pngs(seq, capsys):
    assert main(["probe", "--source", f"folder:{seq}", "--frames", "5", "--json"]) == 0  # all 3, then the end
    records, summary = _json_lines(capsys)
    assert [r["index"] for r in records] == [0, 1, 2]
    for r in records:
        mm = cv2.imread(str(seq / "depth" / f"{r['index']:06d}.png"), cv2.IMREAD_UNCHANGED)
        valid = mm[mm > 0] / 1000.0
        assert (r["width"], r["height"]) == (640, 480) and r["has_color"] is True
        assert r["depth_min_m"] == pytest.approx(valid.min(), abs=1e-4)
        assert r["depth_max_m"] == pytest.approx(valid.max(), abs=1e-4)
        assert r["valid_fraction"] == pytest.approx(valid.size / mm.size, abs=1e-6)
        assert r["intrinsics"] == {"fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5}
        assert "joints2d" not in r
    assert summary["frames_read"] == 3 and summary["frames_skipped"] == 0
    assert summary["measured_fps"] == pytest.approx(30.0, abs=1e-3) and summary["status"] == "ended"


def test_joints_are_the_recorded_simulated_detections(seq, capsys):
    assert main(["probe", "--source", f"folder:{seq}", "--frames", "2", "--json", "--joints", "simulated"]) == 0
    records, summary = _json_lines(capsys)
    truth = [json.loads(line) for line in (seq / "groundtruth.jsonl").read_text().splitlines()]
    assert len(records) == 2 and summary["status"] == "open"  # two of three frames read
    for r in records:
        expected = truth[r["index"]]["detections"]["keypoints"]
        assert r["joints_layout"] == "coco17" and set(r["joints2d"]) == set(expected)
        for name, (x, y, s) in r["joints2d"].items():
            assert [x, y, s] == pytest.approx(expected[name], abs=1e-3)


def test_text_report(seq, capsys):
    assert main(["probe", "--source", str(seq), "--frames", "2", "--joints", "simulated"]) == 0
    out = capsys.readouterr().out
    assert "resolution: 640x480" in out and "intrinsics: fx 525.00  fy 525.00  cx 319.50  cy 239.50" in out
    assert "frame rate: 30.00 Hz measured, 30 Hz nominal" in out
    assert "frame 0: 640x480, t = 0.000 s, depth " in out and "frame 1: 640x480, t = 0.033 s" in out
    assert "joints (coco17, " in out and "score" in out


def test_skipped_frames_are_reported(seq, tmp_path, capsys):
    copy = tmp_path / "seq"
    shutil.copytree(seq, copy)
    (copy / "depth" / "000001.png").unlink()
    assert main(["probe", "--source", f"folder:{copy}", "--json"]) == 0
    records, summary = _json_lines(capsys)
    assert [r["index"] for r in records] == [0, 1, 2]
    assert set(records[1]) == {"index", "timestamp_ns", "skipped"} and "depth/000001.png" in records[1]["skipped"]
    assert summary["frames_read"] == 2 and summary["frames_skipped"] == 1


def test_bad_source_is_one_line_and_status_2(tmp_path, capsys):
    assert main(["probe", "--source", f"kinect:{tmp_path}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown source scheme 'kinect'" in err[0]
    assert main(["probe", "--source", f"mkv:{tmp_path / 'no.mkv'}"]) == 2
    assert "does not exist" in capsys.readouterr().err


@needs_assets
def test_real_still_frame(capsys):
    five = ASSETS / "rgbd" / "kinect_five_people"
    uri = (f"rgbd:{five / 'five_people_color.png'},{five / 'five_people_depth_mm.png'},"
           f"{five / 'five_people_intrinsics.json'}")
    assert main(["probe", "--source", uri]) == 0
    out = capsys.readouterr().out
    assert "depth: 1.759..9.757 m, valid 77.8 % (mean)" in out
    assert "frame rate: not measurable (fewer than 2 frames)" in out
    assert np.isclose(525.0, float(out.split("fx ")[1].split()[0]))
