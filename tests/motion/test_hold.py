"""Holding a motion's frame (``?hold=[AT:]SECONDS``, issue 53's still person).

Oracle: the same motion loaded without the hold. The held frames must equal its frame at AT
exactly, and the motion must go on from the next frame, one frame period after the hold ends;
the synthetic sequence's ground truth of the held frames must then be the same pose, bit for bit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import MOCAP, needs_assets

from swarmpose.cli.main import main
from swarmpose.core.errors import MotionError
from swarmpose.motion.hold import MAX_HOLD_S
from swarmpose.motion.library import load_motion_spec, split_motion_spec

FIELDS = ("angles", "root_offset", "root_rotation")
NO_BODY = None  # a built-in motion is the same on every body


def _assert_held(held, plain, k: int, n: int) -> None:
    """``held`` is ``plain``'s frame k for n frames, then plain's frames k + 1, k + 2, ... exactly."""
    for name in FIELDS:
        a, b = getattr(held, name), getattr(plain, name)
        assert np.array_equal(a[:n], np.repeat(b[k:k + 1], n, axis=0)), name
        rest = len(held) - n
        assert rest > 0 and np.array_equal(a[n:], b[k + 1:k + 1 + rest]), name
    assert held.fps == plain.fps


def test_a_builtin_motion_holds_its_frame_then_goes_on_from_the_next():
    plain = load_motion_spec("builtin:wave", NO_BODY, 200, 30.0)
    held = load_motion_spec("builtin:wave?hold=0.5:1", NO_BODY, 50, 30.0)  # frame 15 held 30 frames
    assert len(held) == 50 and "held 1 s at 0.5 s" in held.name
    _assert_held(held, plain, 15, 30)
    # a hold longer than the frames asked for: the sequence is the hold and the next frame
    assert len(load_motion_spec("builtin:wave?hold=2", NO_BODY, 30, 30.0)) == 60


@needs_assets
def test_a_clip_holds_its_frame_at_the_fps_it_is_resampled_to(makehuman_male):
    clip = str(MOCAP / "bvh11_131_01.bvh")
    plain = load_motion_spec(clip, makehuman_male, 0, 30.0)
    held = load_motion_spec(f"{clip}?hold=1.5:3", makehuman_male, 0, 30.0)
    assert len(held) == 90 + len(plain) - 46
    _assert_held(held, plain, 45, 90)
    # the first frame, with a read option beside the hold (in either order)
    first = load_motion_spec(f"{clip}?hold=2&units=cmu", makehuman_male, 0, 30.0)
    _assert_held(first, plain, 0, 60)
    assert split_motion_spec(f"{clip}?hold=2&units=cmu") == split_motion_spec(f"{clip}?units=cmu")


def test_the_held_frames_of_a_synthetic_sequence_are_one_pose(tmp_path):
    out = tmp_path / "held"
    assert main(["synth", "--motion", "builtin:wave?hold=0.1:0.2", "--frames", "8", "--out", str(out), "--quiet"]) == 0
    rows = [json.loads(line) for line in (out / "groundtruth.jsonl").read_text().splitlines()]
    joints = np.array([[r["joints3d"][j] for j in sorted(r["joints3d"])] for r in rows])
    poses = np.array([r["pose"] for r in rows])
    assert len(rows) == 8
    assert np.array_equal(poses[:6], np.repeat(poses[:1], 6, axis=0))  # 0.2 s at 30 fps
    assert np.array_equal(joints[:6], np.repeat(joints[:1], 6, axis=0))
    assert np.abs(joints[6] - joints[5]).max() > 1e-3  # the wave goes on (its forearm moves ~cm a frame)
    assert json.loads((out / "sequence.json").read_text())["motion_spec"] == "builtin:wave?hold=0.1:0.2"


@pytest.mark.parametrize(("spec", "needle"), [
    ("builtin:wave?hold=", "is not SECONDS or AT:SECONDS"),
    ("builtin:wave?hold=three", "is not SECONDS or AT:SECONDS"),
    ("builtin:wave?hold=1:2:3", "is not SECONDS or AT:SECONDS"),
    ("builtin:wave?hold=nan", "is not SECONDS or AT:SECONDS"),
    ("builtin:wave?hold=0", "must be > 0 s"),
    ("builtin:wave?hold=-1:2", "the start >= 0 s"),
    (f"builtin:wave?hold={MAX_HOLD_S + 1:g}", f"limited to {MAX_HOLD_S:g} s"),
    ("builtin:wave?hold=0.01", "less than one frame at 30 fps"),
    ("builtin:wave?hold=1&hold=2", "given 2 times"),
    ("builtin:wave?hold=1&up=z", "takes only ?hold="),
])
def test_bad_holds_are_clear_errors(spec, needle):
    with pytest.raises(MotionError, match="--motion ") as info:
        load_motion_spec(spec, NO_BODY, 30, 30.0)
    assert needle in str(info.value) and "hold" in str(info.value)


@needs_assets
def test_a_hold_past_the_clip_names_its_length(makehuman_male):
    with pytest.raises(MotionError, match=r"past the motion's end \(249 frames, 8.3 s at 30 fps\)"):
        load_motion_spec(f"{MOCAP / 'bvh11_131_01.bvh'}?hold=9:1", makehuman_male, 0, 30.0)
    with pytest.raises(MotionError, match="hold=\\[AT:\\]SECONDS"):
        load_motion_spec(f"{MOCAP / 'bvh11_131_01.bvh'}?hold=1&speed=2", makehuman_male, 0, 30.0)


def test_synth_says_what_is_wrong_with_a_hold(tmp_path, capsys):
    assert main(["synth", "--motion", "builtin:walk?hold=3s", "--frames", "4", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "hold='3s'" in err and "?hold=SECONDS" in err
