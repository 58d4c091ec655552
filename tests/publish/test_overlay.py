"""The overlay: decoded back with PyAV, every skeleton must be where the message put it, each
person in its id's colour when there are several (pixels compared with the palette, joints
projected by hand from a real body's pose)."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import OutputError
from swarmpose.messages import body_message, frame_message
from swarmpose.publish.overlay import (
    ID_PALETTE,
    LINK_COLOR,
    OverlaySink,
    caption,
    confidence_color,
    draw_bodies,
    id_color,
    video_codec,
)
from swarmpose.sources.base import Frame

W, H = 641, 481  # odd on purpose: the video is 640 x 480
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
    body = body_message(0, "tracking", "", None, np.full((14, 3), 2.0), joints2d, confidence, {"E": 1.0})
    return frame_message("cam0", index, index, 1000, 1000 + 5_000_000, [body])


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


# ---------------------------------------------------------------------------- several people
PEOPLE_INTR = Intrinsics(width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
PEOPLE = {0: -1.3, 2: 0.0, 5: 1.3}
"""Body id -> x (m) of three people standing side by side 3.5 m away (195 px apart, arms 88 px)."""
UPRIGHT = (0.0, 1.0, 0.0, 0.0)  # body frame (Y up) turned 180 degrees about x: upright, facing the camera
FAR_FROM_ARMS = ("head", "neck", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")


@pytest.fixture(scope="module")
def builtin_body():
    from swarmpose.body.loader import load_body

    return load_body("builtin", "default")


def person_pixels(body, x: float, shift_m: float = 0.0) -> np.ndarray:
    """(14, 2) px of the evaluation joints of ``body`` in its rest pose at (x + shift, 0, 3.5) m,
    projected by hand (u = fx X / Z + cx, v = fy Y / Z + cy)."""
    h = body.rest_pose(translation=(x + shift_m, 0.0, 3.5), quaternion=UPRIGHT)
    p = body.posed_points(h[None], EVAL_JOINTS)[0]
    i = PEOPLE_INTR
    return np.stack([i.fx * p[:, 0] / p[:, 2] + i.cx, i.fy * p[:, 1] / p[:, 2] + i.cy], axis=1)


def person(body, body_id: int, shift_m: float = 0.0, state: str = "tracking") -> dict:
    pixels = person_pixels(body, PEOPLE[body_id], shift_m)
    return body_message(body_id, state, "", None, np.full((14, 3), 3.5), pixels, np.full(14, 0.9), {"E": 1.0})


def people_message(body, index: int, shift_m: float = 0.0) -> dict:
    bodies = [person(body, i, shift_m) for i in PEOPLE]
    return frame_message("cam0", index, index, 1000, 1000 + 41_000_000, bodies)


def at(pixels: np.ndarray, name: str) -> tuple[int, int]:
    u, v = pixels[EVAL_JOINTS.index(name)]
    return int(round(u)), int(round(v))


def count(image: np.ndarray, color) -> int:
    return int(np.all(image == np.array(color, np.uint8), axis=-1).sum())


def test_palette_colours_differ_from_each_other_and_from_the_confidence_colours():
    palette = np.array(ID_PALETTE, float)
    assert len(palette) >= 5  # the five-people frame
    pairs = np.linalg.norm(palette[:, None] - palette[None], axis=-1)[np.triu_indices(len(palette), 1)]
    assert pairs.min() > 120
    others = np.array([confidence_color(c) for c in np.linspace(0, 1, 101)] + [LINK_COLOR, (0, 0, 0)], float)
    assert np.linalg.norm(palette[:, None] - others[None], axis=-1).min() > 100
    assert [id_color(i) for i in range(2 * len(ID_PALETTE))] == 2 * list(ID_PALETTE)


def test_draw_bodies_puts_each_id_colour_on_its_own_joints_with_its_number(builtin_body):
    image = np.empty((480, 640, 3), np.uint8)
    image[:] = BACKGROUND
    message = people_message(builtin_body, 0)
    assert draw_bodies(image, message["bodies"]) is image
    for body_id, x in PEOPLE.items():
        own, others = id_color(body_id), [id_color(i) for i in PEOPLE if i != body_id]
        pixels = person_pixels(builtin_body, x)
        for name in EVAL_JOINTS:
            u, v = at(pixels, name)
            assert tuple(image[v, u]) == own, name  # the dot's centre
            window = image[v - 12:v + 13, u - 12:u + 13]
            assert all(count(window, c) == 0 for c in others), name
        mid = ((pixels[EVAL_JOINTS.index("left_knee")] + pixels[EVAL_JOINTS.index("left_ankle")]) / 2).round()
        u, v = int(mid[0]), int(mid[1])
        assert count(image[v - 1:v + 2, u - 1:u + 2], own) > 0  # on the shin, between the dots: the link
        u, v = at(pixels, "head")
        label = image[v - 40:v - 4, u + 6:u + 45]  # up and right of the head, where no link runs
        assert count(label, own) >= 10 and count(label, (0, 0, 0)) >= 10  # the number, outlined in black
        assert all(count(label, c) == 0 for c in others)
    assert near(image[470, 5], BACKGROUND, 0) and near(image[5, 635], BACKGROUND, 0)


def test_one_body_keeps_the_confidence_colours(builtin_body):
    image = np.empty((480, 640, 3), np.uint8)
    image[:] = BACKGROUND
    body = person(builtin_body, 5)
    draw_bodies(image, [body])
    assert all(count(image, c) == 0 for c in ID_PALETTE)
    pixels = person_pixels(builtin_body, PEOPLE[5])
    for name in EVAL_JOINTS:
        u, v = at(pixels, name)
        assert tuple(image[v, u]) == confidence_color(0.9), name
    mid = ((pixels[EVAL_JOINTS.index("left_knee")] + pixels[EVAL_JOINTS.index("left_ankle")]) / 2).round()
    assert tuple(image[int(mid[1]), int(mid[0])]) == LINK_COLOR


def test_caption_counts_the_people(builtin_body):
    msg = people_message(builtin_body, 12)
    assert caption(msg) == "frame 12  3 people  41.0 ms"
    msg["bodies"][1]["state"] = "lost"
    assert caption(msg) == "frame 12  3 people (1 lost)  41.0 ms"
    one = frame_message("cam0", 12, 0, 1000, 1000 + 41_000_000, [person(builtin_body, 0)])
    assert caption(one) == "frame 12  tracking  41.0 ms"  # one person: as before
    one["bodies"][0]["id"] = 5
    assert caption(one) == "frame 12  tracking  person 5  41.0 ms"
    none = frame_message("cam0", 12, 0, 1000, 1000 + 41_000_000, [], "no person")
    assert caption(none) == "frame 12  no body  41.0 ms  no person"


def test_video_of_several_people_colours_each_id(tmp_path, builtin_body):
    path = tmp_path / "overlay.mp4"
    sink = OverlaySink(path, fps=10.0)
    background = np.empty((480, 640, 3), np.uint8)
    background[:] = BACKGROUND
    for k in range(4):
        frame = Frame(k, k * 100_000_000, np.full((480, 640), 3.5, np.float32), background, PEOPLE_INTR)
        sink.frame(people_message(builtin_body, k, shift_m=0.03 * k), frame)
    sink.close()
    frames = decode(path)
    assert len(frames) == 4
    palette = np.array(ID_PALETTE, float)
    for k, image in enumerate(frames):
        for body_id, x in PEOPLE.items():
            pixels = person_pixels(builtin_body, x, 0.03 * k)
            for name in FAR_FROM_ARMS:
                u, v = at(pixels, name)
                got = image[v, u].astype(float)
                nearest = int(np.argmin(np.linalg.norm(palette - got, axis=1)))
                assert ID_PALETTE[nearest] == id_color(body_id) and near(image[v, u], id_color(body_id), 40), \
                    (k, body_id, name, image[v, u])


def test_bodies_at_the_edge_or_without_pixels_are_drawn_without_error(builtin_body):
    image = np.empty((480, 640, 3), np.uint8)
    image[:] = BACKGROUND
    edge = person(builtin_body, 2)
    edge["joints"]["head"]["pixel"] = [636.0, 2.0]  # no room up and right of it: the number stays inside
    edge["joints"]["neck"]["pixel"] = None  # and no link runs from the head
    blind = person(builtin_body, 5)
    for joint in blind["joints"].values():
        joint["pixel"] = None
    draw_bodies(image, [edge, blind])
    assert count(image, id_color(5)) == 0  # nothing to draw for a body without pixels
    assert tuple(image[2, 636]) == id_color(2)  # the head dot
    rows, cols = np.mgrid[:480, :640]
    beside = (np.hypot(cols - 636, rows - 2) > 8) & (rows < 40) & (cols > 560)  # off the dot, in the corner
    assert count(image[beside], id_color(2)) >= 10  # the number
