"""The world frame's floor on given sources: fitted plane, camera height / pitch / roll, fit time.

    .venv/bin/python scripts/floor_check.py SOURCE_URI [SOURCE_URI ...] [--repeat N]

For each source, the first frame's floor by :func:`swarmpose.detect.floor.fit_floor` (Open3D
RANSAC, the fit ``--floor auto`` runs); the median of ``--repeat`` fits is the time (Open3D's
import excluded). A ``swarmpose synth`` folder is also compared with the renderer's camera
(``sequence.json``): the angle between the fitted and the true normal, and the height error.
One JSON line per source.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from swarmpose.core.world import camera_angles
from swarmpose.detect.floor import fit_floor
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source


def first_frame(uri: str) -> Frame:
    source = open_source(uri)
    try:
        return next(item for item in source if isinstance(item, Frame))
    finally:
        source.close()


def truth_of(uri: str) -> tuple[np.ndarray, float] | None:
    """The renderer's floor normal (camera frame) and camera height of a synth folder, else None."""
    folder = Path(uri.removeprefix("folder:"))
    meta = folder / "sequence.json"
    if not meta.is_file():
        return None
    camera = json.loads(meta.read_text())["camera"]
    return np.asarray(camera["world_to_camera_rotation"]) @ [0.0, 1.0, 0.0], float(camera["eye_world_m"][1])


def check(uri: str, repeat: int) -> dict:
    frame = first_frame(uri)
    fit_floor(frame.depth, frame.intrinsics)  # Open3D's import and first call
    times, plane = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        plane = fit_floor(frame.depth, frame.intrinsics)
        times.append(1000 * (time.perf_counter() - t0))
    out = {"source": uri, "size": f"{frame.intrinsics.width}x{frame.intrinsics.height}",
           "fit_ms_median": round(float(np.median(times)), 2), "floor": None}
    if plane is None:
        return out
    pitch, roll = camera_angles(plane.normal)
    out["floor"] = {"camera_height_m": round(plane.offset, 4), "pitch_deg": round(pitch, 2),
                    "roll_deg": round(roll, 2), "inliers": plane.inliers}
    truth = truth_of(uri)
    if truth is not None:
        normal, height = truth
        angle = np.degrees(np.arccos(np.clip(plane.normal @ normal, -1.0, 1.0)))
        out["against_renderer"] = {"normal_error_deg": round(float(angle), 3),
                                   "height_error_m": round(plane.offset - height, 4)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sources", nargs="+", help="source URIs (folder:DIR, rgbd:C,D,K, mkv:FILE, ...)")
    parser.add_argument("--repeat", type=int, default=20, help="fits per source for the time")
    args = parser.parse_args()
    for uri in args.sources:
        print(json.dumps(check(uri, args.repeat)), flush=True)


if __name__ == "__main__":
    main()
