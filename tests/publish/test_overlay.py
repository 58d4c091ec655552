"""The overlay video: decoded back with PyAV, the skeleton must be where the message put it."""

from __future__ import annotations

import re
import shutil
from dataclasses import replace

import numpy as np
import pytest

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import OutputError
from swarmpose.messages import frame_message
from swarmpose.publish.overlay import OverlaySink, video_codec
from swarmpose.sources.base import Frame
from swarmpose.tracking.result import BodyResult

W, H = 641, 481  # odd on purpose: the video is 640 x 480


def body_entry(result: BodyResult, body_id: int = 0) -> dict:
    """One body of a frame message, as the tracker writes it."""
    return replace(result, id=body_id).to_message()
BACKGROUND = (40, 60, 90)
PIXELS = {  # a standing figure, px
    "head": (320, 90), "neck": (320, 140), "left_shoulder": (370, 150), "right_shoulder": (270, 150),
    "left_elbow": (400, 210), "right_elbow": (240, 210), "left_wrist": (410, 270), "right_wrist": (230, 270),
    "left_hip": (350, 270), "right_hip": (290, 270), "left_knee": (355, 350), "right_knee": (285, 350),
    "left_ankle": (360, 430), "right_ankle": (280, 430),
}
LOW = "right_knee"  # drawn with confidence 0 (red); every other joint has 1 (green)


def rgbd_frame(index: int, color: bool = True) -> Frame:
    depth = np.zeros((H, W), np.float32)
    depth[:, W // 2:] = 2.0  # the left half has no measurement
    image = np.empty((H, W, 3), np.uint8)
    image[:] = BACKGROUND
    intr = Intrinsics(width=W, height=H, fx=525.0, fy=525.0, cx=W / 2, cy=H / 2)
    return Frame(index, index * 33_333_333, depth, image if color else None, intr)


def track_message(index: int, shift: int = 0) -> dict:
    joints2d = np.array([PIXELS[j] for j in EVAL_JOINTS], float) + [shift, 0]
    confidence = np.array([0.0 if j == LOW else 1.0 for j in EVAL_JOINTS])
    res = BodyResult(0, "tracking", "", None, np.full((14, 3), 2.0), joints2d, confidence,
                      {"E": 1.0}, {})
    return frame_message("cam0", index, index, 1000, 1000 + 5_000_000, [body_entry(res)])


def decode(path) -> list[np.ndarray]:
    import av

    with av.open(str(path)) as container:
        return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]


def codec_name(path) -> str:
    import av

    with av.open(str(path)) as container:
        return container.streams.video[0].codec_context.name


def near(pixel: np.ndarray, color, tol: float = 20.0) -> bool:
    return bool(np.all(np.abs(pixel.astype(float) - color) <= tol))


def test_skeleton_is_drawn_where_the_message_says(tmp_path):
    path = tmp_path / "overlay.mp4"
    sink = OverlaySink(path, fps=30.0)
    sink.frame(frame_message("cam0", 0, 0, 0, 0, [], "skipped"), None)  # nothing to repeat yet: not written
    for k in range(10):
        sink.frame(track_message(k), rgbd_frame(k))
    sink.frame(frame_message("cam0", 10, 0, 0, 0, [], "skipped: no frame"), None)  # repeats frame 9
    sink.close()
    sink.close()  # idempotent
    frames = decode(path)
    assert len(frames) == 11
    assert codec_name(path) == ("h264" if video_codec() == "libx264" else "mpeg4")
    for image in (frames[0], frames[9], frames[10]):
        assert image.shape == (480, 640, 3)
        x, y = PIXELS["left_hip"]
        r, g, b = image[y, x].astype(int)
        assert g > 150 and r < 100 and b < 100  # a confident joint: green
        x, y = PIXELS[LOW]
        r, g, b = image[y, x].astype(int)
        assert r > 150 and g < 100 and b < 100  # confidence 0: red
        mid = (np.array(PIXELS["left_knee"]) + PIXELS["left_ankle"]) // 2
        assert not near(image[mid[1], mid[0]], BACKGROUND)  # on a link
        assert near(image[400, 560], BACKGROUND) and near(image[40, 600], BACKGROUND)  # far from the figure
    box = frames[0][2:12, 2:100].reshape(-1, 3).astype(int)  # the text line: white on black
    assert box.min(axis=0).max() < 40 and box.max(axis=0).min() > 200


def test_video_plays_before_close_and_follows_the_joints(tmp_path):
    path = tmp_path / "overlay.mp4"
    sink = OverlaySink(path, fps=10.0)
    for k in range(10):
        sink.frame(track_message(k, shift=8 * k), rgbd_frame(k))
    copy = tmp_path / "killed.mp4"  # what a killed process leaves
    shutil.copy(path, copy)
    frames = decode(copy)
    assert len(frames) >= 9  # one fragment per frame; the last one is written with the next
    for k, image in enumerate(frames):
        x, y = PIXELS["head"]
        assert image[y, x + 8 * k, 1] > 150  # the head dot moves with the message
    sink.close()
    assert len(decode(path)) == 10


def test_depth_only_frames_are_drawn_over_the_depth(tmp_path):
    path = tmp_path / "overlay.mp4"
    sink = OverlaySink(path)
    for k in range(3):
        sink.frame(track_message(k), rgbd_frame(k, color=False))
    sink.close()
    frames = decode(path)
    assert len(frames) == 3
    assert frames[0][400, 60].max() < 30  # no depth: black
    assert frames[0][400, 600].max() > 60  # 2 m: a colour of the map
    x, y = PIXELS["left_hip"]
    assert frames[0][y, x, 1] > 150


def test_no_frames_no_file_and_unwritable_path(tmp_path):
    path = tmp_path / "overlay.mp4"
    OverlaySink(path).close()
    assert not path.exists()
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OutputError, match=re.escape(str(blocker / "overlay.mp4"))):
        OverlaySink(blocker / "overlay.mp4")
