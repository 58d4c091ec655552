"""``swarmpose bench overlays``: the tracker on real Kinect frames that have no ground truth,
drawn for a person to judge (``docs/qualitative/``).

* ``skeltrack.png``: the twelve raw Kinect v1 depth frames of ``rgbd/skeltrack_frames``
  (upper bodies, one or two people, no colour) shaded as surfaces
  (:func:`~swarmpose.sources.depth_shading.shaded_normals`), the 2D network run on that image,
  each frame tracked on its own (a fresh start: no previous frame to follow);
* ``five_people.png``: the real Kinect colour + depth frame of five people walking away from
  the camera (``rgbd/kinect_five_people``), tracked with the network on the colour.

With one body: white bones and confidence-coloured dots are the tracked model's joints; with
several, each id in its own colour with its number. Small cyan dots are the network's
keypoints (score >= 0.3). ``max_people`` (the ``settings``) tracks several people per frame.

For each tracked body the report gives two plausibility figures (there is no ground truth):
``span_m``, the distance from the head joint to the middle of the ankles, and, where the
depth shows a floor (:func:`swarmpose.detect.floor.fit_floor`), ``feet_m``, how far the
lower ankle sits above the floor beyond the body's own ankle height at rest (0 = standing on it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmpose.bench.detect import find_assets
from swarmpose.bench.matrix import DETECTORS
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SourceError
from swarmpose.detect.floor import FloorPlane, fit_floor
from swarmpose.pipeline.api import Tracker
from swarmpose.publish.overlay import background, caption, draw_bodies
from swarmpose.sources.base import Frame
from swarmpose.sources.depth_shading import shaded_normals
from swarmpose.sources.still import StillSource
from swarmpose.tracking.result import FrameResult

SKELTRACK = "rgbd/skeltrack_frames"
FIVE_PEOPLE = "rgbd/kinect_five_people"
KINECT_V1 = Intrinsics.kinect_v1()
KEYPOINT_COLOR = (0, 255, 255)


def read_raw_depth(path: Path, width: int = 640, height: int = 480) -> np.ndarray:
    """A headerless little-endian uint16 millimetre depth file -> (height, width) float32 m."""
    raw = np.fromfile(path, dtype="<u2")
    if raw.size != width * height:
        raise SourceError(f"{path} holds {raw.size} 16-bit values, not {width} x {height}; it is not a raw "
                          "Kinect v1 depth frame")
    return raw.reshape(height, width).astype(np.float32) / 1000.0


def skeltrack_frames(assets: Path) -> list[Frame]:
    """The Skeltrack frames, in name order, with the shaded depth as their colour image."""
    paths = sorted((assets / SKELTRACK).glob("depth-data-*"))
    frames = []
    for i, path in enumerate(paths):
        depth = read_raw_depth(path)
        frames.append(Frame(i, 0, depth, shaded_normals(depth, KINECT_V1), KINECT_V1))
    return frames


def five_people_frame(assets: Path) -> Frame:
    """The five-people frame (colour, registered depth, its intrinsics)."""
    folder = assets / FIVE_PEOPLE
    return StillSource(folder / "five_people_color.png", folder / "five_people_depth_mm.png",
                       folder / "five_people_intrinsics.json").frame


def draw(frame: Frame, result: FrameResult) -> np.ndarray:
    """(H, W, 3) uint8: the frame's image with the tracked skeleton, the keypoints and the caption."""
    import cv2

    image = background(frame)
    message = result.to_message()
    for body in result.bodies:
        if body.detection is not None:
            for x, y, score in body.detection.keypoints:
                if score >= 0.3:
                    cv2.circle(image, (int(round(x)), int(round(y))), 2, KEYPOINT_COLOR, -1, cv2.LINE_AA)
    draw_bodies(image, message.get("bodies") or [])
    text = caption(message)
    cv2.putText(image, text, (5, image.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return image


def ankle_rest_height(body: SkinnedBody) -> float:
    """Height (m) of the body's ankle joints above its soles in the rest pose (rest mesh: y up)."""
    return float(np.mean([body.point(a)[1] for a in ("left_ankle", "right_ankle")]) + body.floor_offset)


def plausibility(joints3d: np.ndarray, floor: FloorPlane | None, ankle_height_m: float) -> dict:
    """``span_m`` (head to mid-ankle, m) and ``feet_m`` (lower ankle above the floor minus
    ``ankle_height_m``; None without a floor) of a body's joints (J, 3) m, ``EVAL_JOINTS`` order."""
    j = {name: np.asarray(joints3d[k], float) for k, name in enumerate(EVAL_JOINTS)}
    ankles = np.stack([j["left_ankle"], j["right_ankle"]])
    span = float(np.linalg.norm(j["head"] - ankles.mean(axis=0)))
    feet = None if floor is None else float(floor.height(ankles).min() - ankle_height_m)
    return {"span_m": round(span, 3), "feet_m": None if feet is None else round(feet, 3)}


def montage(images: list[np.ndarray], columns: int = 4, scale: float = 0.5) -> np.ndarray:
    """Images (H, W, 3) of one size, shrunk by ``scale``, in a grid of ``columns`` (black padding)."""
    import cv2

    small = [cv2.resize(im, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) for im in images]
    h, w = small[0].shape[:2]
    rows = -(-len(small) // columns)
    grid = np.zeros((rows * h, columns * w, 3), np.uint8)
    for k, im in enumerate(small):
        r, c = divmod(k, columns)
        grid[r * h:(r + 1) * h, c * w:(c + 1) * w] = im
    return grid


def write_overlays(out: Path, *, detector: str = "movenet", assets: str | Path | None = None,
                   settings: dict | None = None) -> dict[str, dict]:
    """Track and draw the frames (module doc) into ``out``; per picture, each frame's state and reason."""
    import cv2

    root = find_assets(assets).resolve()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    spec = DETECTORS[detector].format(assets=root)
    report = {}
    pictures = {"skeltrack.png": skeltrack_frames(root), "five_people.png": [five_people_frame(root)]}
    for name, frames in pictures.items():
        with Tracker(detector=spec, **(settings or {})) as tracker:  # ids from 0 in each picture
            ankle_height = ankle_rest_height(tracker.body)
            images, states, bodies = [], [], []
            for frame in frames:
                tracker.reset()  # the detector too: BlazePose would crop the last picture's regions
                result = tracker.track_frame(frame)
                images.append(draw(frame, result))
                states.append(", ".join(f"{b.id}: {b.state}" for b in result.bodies) if result.bodies
                              else f"no body: {result.reason}")
                floor = fit_floor(frame.depth, frame.intrinsics)
                bodies.append([{"id": b.id, "state": b.state, **plausibility(b.joints3d, floor, ankle_height)}
                               for b in result.bodies if b.state != "lost"])
            picture = montage(images) if len(images) > 1 else images[0]
            cv2.imwrite(str(out / name), picture[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
            report[name] = {"frames": len(frames), "states": states, "bodies": bodies}
    return report
