#!/usr/bin/env python3
"""Track people in RGBD frames from your own camera code, with the swarmpose Python API.

    python examples/track_my_camera.py SEQUENCE_FOLDER [--detector onnx:movenet.onnx] [--frames 10]

``my_camera()`` stands for your capture loop: here it reads a sequence folder written by
``swarmpose synth`` (colour/*.png, depth/*.png in millimetres, intrinsic.json) with OpenCV,
the way you would read any camera: float32 depth in metres (0 = no measurement) and uint8
RGB registered to it. Each frame's result is printed, and sent on as the protocol's frame
message (here: one JSON line on stdout per frame with --json).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

import swarmpose


def my_camera(folder: Path) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
    """(depth m float32, RGB uint8, capture time ns) per frame, read with OpenCV."""
    for i, depth_png in enumerate(sorted((folder / "depth").glob("*.png"))):
        depth_mm = cv2.imread(str(depth_png), cv2.IMREAD_UNCHANGED)
        bgr = cv2.imread(str(folder / "color" / depth_png.name), cv2.IMREAD_COLOR)
        yield depth_mm.astype(np.float32) / 1000.0, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), int(i * 1e9 / 30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a sequence folder (swarmpose synth --out ...)")
    parser.add_argument("--detector", default="simulated",
                        help="2D joints: onnx:MODEL.onnx (MoveNet, BlazePose) or simulated (the folder's own)")
    parser.add_argument("--frames", type=int, default=10, help="frames to track")
    parser.add_argument("--particles", type=int, default=32, help="PSO particles (64 is the paper's)")
    parser.add_argument("--generations", type=int, default=32, help="PSO generations (64 is the paper's)")
    parser.add_argument("--json", action="store_true", help="print each frame message as a JSON line")
    args = parser.parse_args()

    # your camera's pinhole: swarmpose.Intrinsics(width, height, fx, fy, cx, cy); here read from the folder
    K = swarmpose.Intrinsics.load(args.folder / "intrinsic.json")
    # the simulated detector replays the folder's recorded detections: it needs the folder as a source
    source = swarmpose.open_source(f"folder:{args.folder}") if args.detector == "simulated" else None

    with swarmpose.Tracker(body="builtin", detector=args.detector, intrinsics=K, source=source,
                           particles=args.particles, generations=args.generations) as tracker:
        for n, (depth_m, rgb, t_ns) in enumerate(my_camera(args.folder)):
            if n >= args.frames:
                break
            result = tracker.track(depth_m, rgb, timestamp_ns=t_ns)
            if args.json:
                print(json.dumps(result.to_message(camera="kinect0")))
                continue
            for body in result.bodies:
                wrist = body.joints["left_wrist"].position_m
                where = "unknown" if wrist is None else "({:+.3f}, {:+.3f}, {:+.3f}) m".format(*wrist)
                print(f"frame {result.index}: body {body.id} {body.state:<8} left wrist {where}")
            if not result.bodies:
                print(f"frame {result.index}: nobody ({result.reason})")
    if source is not None:
        source.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
