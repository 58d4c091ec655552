"""Personalisation on real data (issue 15): UTD-MHAD subjects s1-s3 personalised from real Kinect v1
depth, the fitted body's limb lengths against the medians of the Kinect SDK skeleton's, and its
height against the height measured on the depth (`swarmpose.sources.utdmhad.measured_height`).

usage: .venv/bin/python scripts/personalise_utdmhad.py [ACTION ...] [--frames N] [--body SPEC] [--detector SPEC]
One JSON line per (subject, action). The Kinect skeleton's joint centres are Microsoft's, not a rig's
(its hips sit wider and higher than a skeleton's), so the limb lengths compare definitions as well.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.personalise.personalise import body_measures
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.personalise_run import personalise
from swarmpose.sources.utdmhad import UtdMhadSource, measured_height

ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "assets"
LIMBS = {"upper_arm": ("shoulder", "elbow"), "forearm": ("elbow", "wrist"), "thigh": ("hip", "knee"),
         "shin": ("knee", "ankle")}


def kinect_limbs(joints3d: np.ndarray) -> dict[str, float]:
    """Median over frames and both sides of each limb's length (m) in (F, J, 3) joints."""
    out = {}
    for limb, (a, b) in LIMBS.items():
        ends = [(EVAL_JOINTS.index(f"{s}_{a}"), EVAL_JOINTS.index(f"{s}_{b}")) for s in ("left", "right")]
        lengths = [np.linalg.norm(joints3d[:, i] - joints3d[:, j], axis=1) for i, j in ends]
        out[limb] = float(np.nanmedian(np.concatenate(lengths)))
    return out


def body_limbs(body) -> dict[str, float]:
    """Each limb's rest length (m), mean of both sides."""
    return {limb: float(np.mean([np.linalg.norm(body.point(f"{s}_{a}") - body.point(f"{s}_{b}"))
                                 for s in ("left", "right")])) for limb, (a, b) in LIMBS.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("actions", nargs="*", type=int, default=[23])
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--subjects", default="s1,s2,s3")
    p.add_argument("--body", default=f"makehuman:{ASSETS / 'bodies' / 'makehuman'}")
    p.add_argument("--detector", default="simulated")
    args = p.parse_args()
    folder = ASSETS / "rgbd" / "utd_mhad" / "depth"
    for subject in args.subjects.split(","):
        for action in args.actions:
            path = folder / f"a{action}_{subject}_t1_depth.mat"
            source = UtdMhadSource(path)
            truth = kinect_limbs(source.ground_truth.joints3d)
            measured = measured_height(source.depth[0], source.intrinsics)
            config = ServiceConfig(source=f"utdmhad:{path}", body=args.body, detector=args.detector)
            result = personalise(config, args.frames, show_progress=False)
            fitted = body_limbs(result.fit.body)
            print(json.dumps({"subject": subject, "action": action, "detector": args.detector,
                              **body_measures(result.fit.body), "measured_height_m": round(measured, 3),
                              "parameters": result.fit.parameters,
                              "limbs_cm": {k: [round(100 * fitted[k], 1), round(100 * truth[k], 1)] for k in LIMBS},
                              "frames_tracked": len(result.samples), "seconds": round(result.fit.seconds, 1)}),
                  flush=True)


if __name__ == "__main__":
    main()
