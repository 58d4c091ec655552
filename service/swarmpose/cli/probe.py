"""``swarmpose probe``: read a few frames of a source and describe them.

Per frame: resolution, intrinsics, the depth range (m) of the valid pixels and their share,
and with a detector the 2D joints with their scores; over the frames: the frame rate
measured from the timestamps and the source's final status.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from swarmpose.cli.common import DEFAULTS, positive_int
from swarmpose.tracking.config import tracker_default

if TYPE_CHECKING:  # the sources and detectors are imported by the command that reads them
    from swarmpose.sources.base import Frame, FrameSource


def frame_record(frame: Frame, joints=None) -> dict:
    """One frame as a JSON-ready dict: index, timestamp_ns, width, height, intrinsics,
    depth_min_m / depth_max_m (valid pixels; None when there are none), valid_fraction,
    has_color and, with ``joints`` (:class:`~swarmpose.detect.joints.Joints2D`), joints2d."""
    depth = frame.depth
    valid = depth[(depth > 0) & np.isfinite(depth)]
    k = frame.intrinsics
    record = {
        "index": frame.index, "timestamp_ns": frame.timestamp_ns, "width": frame.size[0], "height": frame.size[1],
        "intrinsics": {"fx": round(k.fx, 4), "fy": round(k.fy, 4), "cx": round(k.cx, 4), "cy": round(k.cy, 4)},
        "depth_min_m": round(float(valid.min()), 4) if valid.size else None,
        "depth_max_m": round(float(valid.max()), 4) if valid.size else None,
        "valid_fraction": round(valid.size / depth.size, 6), "has_color": frame.color is not None,
    }
    if joints is not None:
        record["joints_layout"] = joints.layout.name
        record["joints2d"] = joints.as_dict()
    return record


def probe_records(source: FrameSource, frames: int = 10, joints: str | None = None,
                  models: str = "") -> Iterator[dict]:
    """Up to ``frames`` per-frame records (skipped frames as ``{index, timestamp_ns, skipped}``); with
    ``joints`` a detector spec (named networks from ``models`` first), each frame's 2D joints."""
    from swarmpose.detect.registry import make_detector
    from swarmpose.sources.base import SkippedFrame

    detector = None
    if joints:
        detector = make_detector(joints, source, models)
    try:
        count = 0
        for item in source:
            if isinstance(item, SkippedFrame):
                yield {"index": item.index, "timestamp_ns": item.timestamp_ns, "skipped": item.reason}
            else:
                yield frame_record(item, detector.detect(item) if detector is not None else None)
            count += 1
            if count >= frames:
                break
    finally:
        if detector is not None:
            detector.close()


def summary(records: list[dict], source: FrameSource) -> dict:
    """Totals over the records: frames read and skipped, the measured frame rate (Hz, from the
    timestamps of the frames read), the depth range over all frames and the source's status."""
    read = [r for r in records if "skipped" not in r]
    stamps = sorted(r["timestamp_ns"] for r in read)
    gaps = np.diff(stamps)
    fps = float(1e9 / np.median(gaps)) if len(gaps) and np.median(gaps) > 0 else None
    mins = [r["depth_min_m"] for r in read if r["depth_min_m"] is not None]
    maxs = [r["depth_max_m"] for r in read if r["depth_max_m"] is not None]
    return {
        "source": source.uri, "status": source.status, "frames_read": len(read),
        "frames_skipped": len(records) - len(read), "measured_fps": round(fps, 3) if fps else None,
        "nominal_fps": getattr(source, "fps", None), "length": source.length,
        "depth_min_m": min(mins) if mins else None, "depth_max_m": max(maxs) if maxs else None,
        "mean_valid_fraction": round(float(np.mean([r["valid_fraction"] for r in read])), 6) if read else None,
    }


def format_record(r: dict) -> str:
    """One readable line (plus joint lines) for a record."""
    if "skipped" in r:
        return f"frame {r['index']}: skipped ({r['skipped']})"
    depth = (f"depth {r['depth_min_m']:.3f}..{r['depth_max_m']:.3f} m" if r["depth_min_m"] is not None
             else "no valid depth")
    line = (f"frame {r['index']}: {r['width']}x{r['height']}, t = {r['timestamp_ns'] / 1e9:.3f} s, {depth}, "
            f"valid {100 * r['valid_fraction']:.1f} %" + ("" if r["has_color"] else ", no colour"))
    if "joints2d" in r:
        from swarmpose.tracking.init_pose import torso_enough

        least = tracker_default("min_score")  # what the tracker counts as a detected keypoint
        found = {k: v for k, v in r["joints2d"].items() if v[2] >= least}
        person = torso_enough(found)  # what a track starts on
        line += (f"\n  joints ({r['joints_layout']}, {len(found)}/{len(r['joints2d'])} with a score of at least "
                 f"{least:g}, the tracker's --min-score)"
                 + (":" if person else ": no person found (no torso: both shoulders, both hips or 3 of 4)"))
        for name, (x, y, s) in found.items():
            line += f"\n    {name:<16} {x:8.1f} {y:8.1f}  score {s:.2f}"
    return line


def format_summary(s: dict, first: dict | None) -> str:
    """The readable header: source, resolution, intrinsics, depth range, frame rate, status."""
    lines = [f"source: {s['source']} ({s['status']})",
             f"frames: {s['frames_read']} read, {s['frames_skipped']} skipped"
             + (f" of {s['length']}" if s["length"] else "")]
    if first is not None:
        k = first["intrinsics"]
        lines.append(f"resolution: {first['width']}x{first['height']}")
        lines.append(f"intrinsics: fx {k['fx']:.2f}  fy {k['fy']:.2f}  cx {k['cx']:.2f}  cy {k['cy']:.2f}")
    if s["depth_min_m"] is not None:
        lines.append(f"depth: {s['depth_min_m']:.3f}..{s['depth_max_m']:.3f} m, "
                     f"valid {100 * s['mean_valid_fraction']:.1f} % (mean)")
    fps = f"{s['measured_fps']:.2f} Hz measured" if s["measured_fps"] else "not measurable (fewer than 2 frames)"
    if s.get("nominal_fps"):
        fps += f", {s['nominal_fps']:g} Hz nominal"
    lines.append(f"frame rate: {fps}")
    return "\n".join(lines)


def run_probe(uri: str, frames: int = 10, joints: str | None = None, as_json: bool = False, out=None,
              models: str = "") -> int:
    """Open ``uri``, read ``frames`` frames, print per-frame lines (JSON objects with ``as_json``,
    then a ``{"summary": …}`` object) or a readable report; returns the exit status (0)."""
    from swarmpose.sources.registry import open_source

    out = out or sys.stdout
    with open_source(uri) as source:
        records = []
        for record in probe_records(source, frames, joints, models):
            records.append(record)
            if as_json:
                print(json.dumps(record), file=out, flush=True)
        total = summary(records, source)
    if as_json:
        print(json.dumps({"summary": total}), file=out)
    else:
        first = next((r for r in records if "skipped" not in r), None)
        print(format_summary(total, first), file=out)
        for r in records:
            print(format_record(r), file=out)
    return 0


def cmd_probe(args: argparse.Namespace) -> int:
    """Read a few frames of a source and describe them (resolution, intrinsics, depth, rate, joints)."""
    return run_probe(args.source, frames=args.frames, joints=args.detector, as_json=args.json,
                     models=args.models or "")


def add_probe_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``probe``."""
    p = sub.add_parser("probe", parents=[common], formatter_class=DEFAULTS,
                       help="read a few frames of a source: resolution, intrinsics, depth range, rate, joints")
    p.add_argument("--source", required=True, help="folder:DIR, rgbd:C.png,D.png,K.json, mkv:FILE, bag:FILE, "
                                                   "utdmhad:FILE.mat, realsense:[SERIAL], azure:[INDEX], "
                                                   "openni2:[FILE.oni|URI]")
    p.add_argument("--detector", "--joints", dest="detector", default=None,
                   help="also detect 2D joints: movenet, blazepose, simulated, onnx:MODEL, openpose-json:DIR")
    p.add_argument("--models", default=None, help="the folder movenet and blazepose are looked for in first")
    p.add_argument("--frames", type=positive_int, default=10, help="frames to read")
    p.add_argument("--json", action="store_true", help="one JSON object per frame, then a summary object")
    p.set_defaults(func=cmd_probe)
