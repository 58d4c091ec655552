"""Benchmark of the ONNX 2D detectors: time per frame and accuracy on a real photo.

For each network in ``assets/pose2d`` (MoveNet single-pose lightning, BlazePose full
landmark) on onnxruntime's CPU provider:

* ``coco_ms``: median time of ``detect()`` (crop, resize, inference, decoding) on the COCO
  photo ``images/coco_val2017_000000000785.jpg`` (640x425), as in the accuracy check;
* ``vga_ms``: the same on the real 640x480 Kinect colour frame ``rgbd/kinect_five_people``,
  without a box (MoveNet: whole frame; BlazePose: follows its previous detection);
* ``coco_median_error_px``: median distance (px) between the detected and the annotated
  COCO keypoints over the visible ones; MoveNet sees the whole photo, BlazePose the
  annotated person box enlarged by the crop margin.

Medians after ``warmup`` untimed runs. CLI: ``swarmpose bench detect [--repeats N] [--json]``.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import replace
from functools import partial
from itertools import count
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import COCO17
from swarmpose.core.assets import asset_folders
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.detect.onnx_pose import OnnxPoseDetector, default_threads
from swarmpose.sources.base import Frame

COCO_PHOTO = "images/coco_val2017_000000000785.jpg"
COCO_KEYPOINTS = "images/coco_val2017_000000000785_keypoints.json"
VGA_FRAME = "rgbd/kinect_five_people/five_people_color.png"
MODELS = {"movenet": "pose2d/movenet_singlepose_lightning.onnx",
          "blazepose": "pose2d/blazepose_landmark_full.onnx"}


def find_assets(assets: str | Path | None = None) -> Path:
    """The shared assets folder: ``assets``, else the first of :func:`~swarmpose.core.assets.asset_folders`
    that holds the COCO photo. ConfigError when none does."""
    candidates = [Path(assets).expanduser()] if assets else asset_folders()
    for path in candidates:
        if (path / COCO_PHOTO).is_file():
            return path
    raise ConfigError(f"no assets folder with {COCO_PHOTO} found (looked in {', '.join(map(str, candidates))}); "
                      "pass --assets DIR or set SWARMPOSE_ASSETS")


def image_frame(path: Path, index: int = 0) -> Frame:
    """A :class:`Frame` holding the RGB image at ``path`` (depth all invalid, nominal intrinsics)."""
    import cv2

    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ConfigError(f"cannot read image {path}")
    h, w = bgr.shape[:2]
    intr = Intrinsics(w, h, 525.0, 525.0, (w - 1) / 2, (h - 1) / 2)
    return Frame(index, 0, np.zeros((h, w), np.float32), cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), intr)


def coco_annotation(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The photo's one person: keypoints (17, 3) x px, y px, v (0 unlabelled, 1 occluded, 2 visible)
    in COCO order, and its box [x0, y0, x1, y1] px."""
    ann = json.loads(Path(path).read_text())["annotations"][0]
    x, y, w, h = ann["bbox"]
    return np.asarray(ann["keypoints"], dtype=np.float64).reshape(17, 3), np.array([x, y, x + w, y + h])


def coco_median_error(joints, truth: np.ndarray) -> float:
    """Median pixel distance between ``joints`` (a Joints2D of any layout naming the COCO-17 keypoints)
    and ``truth`` (17, 3) over the labelled keypoints (v > 0)."""
    index = [joints.layout.keypoints.index(name) for name in COCO17.keypoints]
    xy = joints.keypoints[index, :2]
    labelled = truth[:, 2] > 0
    return float(np.median(np.linalg.norm(xy[labelled] - truth[labelled, :2], axis=1)))


def _time_ms(fn, repeats: int, warmup: int) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


def bench_detectors(repeats: int = 20, assets: str | Path | None = None, threads: int | None = None,
                    warmup: int = 2) -> dict:
    """Time and accuracy of each ONNX detector (see the module doc).

    Returns ``{"threads", "repeats", "cpu_count", "detectors": {name: {"model", "layout",
    "coco_ms", "vga_ms", "coco_median_error_px", "coco_crop"}}}``.
    """
    if repeats < 1:
        raise ConfigError(f"--repeats must be at least 1, got {repeats}")
    root = find_assets(assets)
    photo = image_frame(root / COCO_PHOTO)
    vga = image_frame(root / VGA_FRAME, index=1)
    truth, box = coco_annotation(root / COCO_KEYPOINTS)
    threads = threads or default_threads()
    out = {"threads": threads, "repeats": repeats, "cpu_count": os.cpu_count(), "detectors": {}}
    for name, rel in MODELS.items():
        detector = OnnxPoseDetector(root / rel, adapter=name, threads=threads)
        crop = None if name == "movenet" else box
        try:
            error = coco_median_error(detector.detect(photo, crop), truth)
            coco_ms = _time_ms(partial(detector.detect, photo, crop), repeats, warmup)
            detector.reset()  # each timed frame its own index: BlazePose follows the one before
            frames = (replace(vga, index=k) for k in count(1))
            vga_ms = _time_ms(partial(_detect_next, detector, frames), repeats, warmup)
        finally:
            detector.close()
        out["detectors"][name] = {
            "model": rel, "layout": detector.layout.name, "coco_ms": round(coco_ms, 3), "vga_ms": round(vga_ms, 3),
            "coco_median_error_px": round(error, 3),
            "coco_crop": "whole photo padded to a square" if crop is None else "annotated box x margin",
        }
    return out


def _detect_next(detector: OnnxPoseDetector, frames) -> None:
    """Detect the next of ``frames`` (an iterator of Frames), without a box."""
    detector.detect(next(frames))


def format_detect_bench(result: dict) -> str:
    """Human-readable lines of :func:`bench_detectors`'s result."""
    lines = [f"ONNX 2D detectors, onnxruntime CPU, {result['threads']} thread(s), {result['cpu_count']} cores, "
             f"median of {result['repeats']}"]
    for name, row in result["detectors"].items():
        lines.append(f"  {name:10s} COCO photo {row['coco_ms']:7.2f} ms  640x480 {row['vga_ms']:7.2f} ms  "
                     f"COCO median error {row['coco_median_error_px']:.2f} px ({row['coco_crop']})")
    return "\n".join(lines)
