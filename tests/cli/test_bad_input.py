"""Regression tests of the bad-input sweep (scripts/bad_input_sweep.py, docs/bad-input.md).

Each test damages a copy of a small synthetic sequence the way one case of the sweep did, runs
the real command line and checks the exit status and that the message names the input. The
oracles are independent of the code under test: the files are read back with the json and csv
modules, the BVH with the motion reader and the video with PyAV.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from swarmpose.cli.main import main
from swarmpose.core.polling import wait_until
from swarmpose.sources.base import SKIP_WARNINGS

LIFT = ("--mode", "lift", "--no-overlay")
"""Tracking without the model search: a run over a few frames takes a fraction of a second."""


@pytest.fixture
def seq(wave_sequence, tmp_path) -> Path:
    """A copy of the 6-frame synthetic sequence, to damage."""
    return Path(shutil.copytree(wave_sequence, tmp_path / "seq"))


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return next(line for line in err.splitlines() if line.startswith("swarmpose: error:"))


def _set_intrinsics(seq: Path, **values) -> None:
    data = {"width": 640, "height": 480, "fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5, **values}
    (seq / "intrinsic.json").write_text(json.dumps(data, allow_nan=True))


@pytest.mark.parametrize("values", [{"fx": float("nan")}, {"fy": float("nan")}, {"cx": float("inf")},
                                    {"cy": float("-inf")}, {"fx": 0.0}])
def test_intrinsics_that_are_not_finite_or_positive_are_refused(seq, capsys, values):
    # NaN fx passed the "fx <= 0" check and every frame was tracked as "no person" with exit status 0
    _set_intrinsics(seq, **values)
    assert main(["track", str(seq), "--out", str(seq.parent / "out"), *LIFT]) == 2
    line = _error_line(capsys)
    assert str(seq / "intrinsic.json") in line and "calibration" in line
    assert not (seq.parent / "out" / "poses.jsonl").exists()


@pytest.mark.parametrize("convert", [lambda d: (d // 20).astype(np.uint8), lambda d: np.dstack([d, d, d])],
                         ids=["8-bit", "3-channel"])
def test_depth_images_that_are_not_16_bit_single_channel_are_refused(seq, capsys, convert):
    # every frame used to be skipped one by one, silently, and the run exited 0
    for path in sorted((seq / "depth").glob("*.png")):
        assert cv2.imwrite(str(path), convert(cv2.imread(str(path), cv2.IMREAD_UNCHANGED)))
    assert main(["replay", str(seq), "--out", str(seq.parent / "out"), *LIFT]) == 2
    line = _error_line(capsys)
    assert str(seq) in line and "000000.png" in line and "16-bit" in line


def test_a_folder_whose_image_folders_are_empty_is_refused(seq, capsys):
    # sequence.json promised 6 frames: each was skipped as missing and the run exited 0
    for path in [*(seq / "depth").iterdir(), *(seq / "color").iterdir()]:
        path.unlink()
    assert main(["track", str(seq), "--out", str(seq.parent / "out"), *LIFT]) == 2
    line = _error_line(capsys)
    assert str(seq) in line and "no images" in line


def test_a_skipped_frame_is_named_in_a_warning_and_the_run_goes_on(seq, capsys):
    (seq / "depth" / "000002.png").write_bytes(b"\x89PNG garbage")
    out = seq.parent / "out"
    assert main(["track", str(seq), "--out", str(out), *LIFT]) == 0
    err = capsys.readouterr().err
    warning = next(line for line in err.splitlines() if "frame 2 skipped" in line)
    assert str(seq / "depth" / "000002.png") in warning
    messages = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    assert [m["frame"] for m in messages] == list(range(6))
    assert messages[2]["reason"].startswith("skipped:") and not messages[2]["bodies"]
    assert all(m["bodies"] for i, m in enumerate(messages) if i != 2)


def test_skipped_frames_are_named_up_to_a_limit_and_a_source_of_nothing_but_them_fails(seq, capsys):
    frames = SKIP_WARNINGS + 3
    for path in [*(seq / "depth").iterdir(), *(seq / "color").iterdir()]:
        path.unlink()
    for i in range(frames):
        (seq / "depth" / f"{i:06d}.png").write_bytes(b"not a png")
        (seq / "color" / f"{i:06d}.png").write_bytes(b"not a png")
    sequence = json.loads((seq / "sequence.json").read_text())
    (seq / "sequence.json").write_text(json.dumps({**sequence, "frames": frames}))
    out = seq.parent / "out"
    assert main(["track", str(seq), "--out", str(out), *LIFT]) == 1
    err = capsys.readouterr().err.splitlines()
    named = [line for line in err if " skipped: depth image " in line]
    assert len(named) == SKIP_WARNINGS
    assert sum("more frames skipped" in line for line in err) == 1
    last = next(line for line in err if "ended with an error" in line)
    assert f"none of its {frames} frames could be read" in last and "000000.png" in last
    assert len((out / "poses.jsonl").read_text().splitlines()) == frames


def test_a_depth_without_valid_pixels_is_said_in_the_log_and_each_frame_message(seq, capsys):
    for path in sorted((seq / "depth").glob("*.png")):
        assert cv2.imwrite(str(path), np.zeros((480, 640), np.uint16))
    out = seq.parent / "out"
    assert main(["track", str(seq), "--out", str(out), "--frames", "3", *LIFT]) == 0
    err = capsys.readouterr().err.splitlines()
    assert sum("no valid pixels" in line for line in err) == 2  # once for the frames, once for the run
    assert any(line.startswith("swarmpose: nobody was tracked in the 3 frames read (frame 0: the depth image")
               for line in err)
    messages = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    assert len(messages) == 3 and all("no valid pixels" in m["reason"] and not m["bodies"] for m in messages)


def _readable(out: Path) -> tuple[int, int, int, int]:
    """(poses.jsonl lines, poses.csv rows, poses.bvh frames, overlay.mp4 frames), each read back."""
    import csv

    import av

    from swarmpose.motion.bvh import read_bvh

    lines = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    with open(out / "poses.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert len({len(r) for r in rows}) == 1
    with av.open(str(out / "overlay.mp4")) as container:
        video = sum(1 for _ in container.decode(video=0))
    return len(lines), len(rows) - 1, len(read_bvh(out / "poses.bvh")), video


@pytest.mark.slow
def test_sigterm_stops_track_with_every_file_closed_and_readable(wave_sequence, tmp_path):
    # track had no SIGTERM handler: Python died at once without closing its files; now the
    # frame in progress is finished and handed to every file, so all of them hold the same frames
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "swarmpose", "track", str(wave_sequence), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    jsonl = out / "poses.jsonl"
    wait_until(lambda: proc.poll() is not None or (jsonl.is_file() and jsonl.read_bytes().count(b"\n") >= 2), 240,
               0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "swarmpose: interrupted; the outputs hold the frames tracked so far" in err
    frames, rows, bvh, video = _readable(out)
    assert 2 <= frames < 6
    assert rows == frames and bvh == frames and video == frames


def test_an_opencl_device_that_is_not_there_stops_the_run(seq, capsys):
    # every frame used to be "tracking failed: no OpenCL device matches" with exit status 0
    out = seq.parent / "out"
    assert main(["track", str(seq), "--out", str(out), "--device", "nonsense", "--no-overlay"]) == 2
    line = _error_line(capsys)
    assert "no OpenCL device matches 'nonsense'" in line and "available:" in line
    assert main(["replay", str(seq), "--out", str(out), "--device", "nonsense", "--no-overlay"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "'nonsense'" in err
    assert (out / "poses.jsonl").read_text() == ""


@pytest.mark.parametrize("argv, flag", [(["subscribe", "--timeout", "-1"], "--timeout"),
                                        (["subscribe", "--count", "-1"], "--count"),
                                        (["health", "--max-age", "nan"], "--max-age")])
def test_negative_counts_and_times_are_refused_by_name(capsys, argv, flag):
    # subscribe --timeout -1 ended in a ValueError traceback, --count -1 waited and exited 0
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"argument {flag}:" in err
