"""``swarmpose bench track``: end-to-end frames per second of the tracker on a fixed synthetic
sequence, with the split of a generation and the accuracy of the same run.

The sequence is rendered once per call into a temporary folder: ``frames`` frames of
``motion`` (default ``builtin:walk``, so the benchmark needs no assets) on ``body`` seen
from the front at 3 m, with the simulated detector. It is tracked ``repeats`` times with
the same settings (the seeded PSO repeats exactly); figures are medians over the repeats.

Reported (see :func:`bench_track`):

* ``fps``: frames per second of detection + tracking over the whole sequence (the start on
  the first frame included); ``tracking_fps``: over the frames after the first;
* ``split_ms``: per generation (objective call) of the per-frame search, means over the
  tracked frames (medians over the repeats): ``score`` (the launch and its wait: forward
  kinematics, the depth term and the joint terms on the device), ``joint_term`` (combining
  the terms on the host), ``pso_update`` (the swarm's arithmetic),
  and ``other_per_frame`` (ms per frame outside the search: detection, the box, the
  re-checks, the verdict);
* ``mpjpe_mm`` Δ and ``A100`` against the ground truth.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from swarmpose.bench.accuracy import scores, track_with_truth
from swarmpose.body.loader import load_body
from swarmpose.core.progress import progress_bar
from swarmpose.motion.library import load_motion_spec
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.sim.synth import SynthConfig, synthesize
from swarmpose.tracking.config import TrackerConfig

SPLIT = ("score", "joint_term", "pso_update")


def _split(timings: list[dict], evaluations: int) -> dict[str, float]:
    """Per-generation means over the tracked frames (the first, the start, left out when there
    are others), so that the parts add up to the total."""
    rows = [t for t in timings[1:] if "pso" in t] or [t for t in timings if "pso" in t]
    if not rows:
        return {}
    out = {k: float(np.mean([t.get(k, 0.0) for t in rows])) / evaluations for k in SPLIT}
    out["total"] = float(np.mean([t["pso"] for t in rows])) / evaluations
    out["other_per_frame"] = float(np.mean([t["total"] - t["pso"] for t in rows]))
    return out


def bench_track(body: str = "builtin", shape: str | None = None, motion: str = "builtin:walk", frames: int = 30,
                repeats: int = 3, tracker: TrackerConfig | None = None, progress: bool = True) -> dict:
    """Frames per second, split and Δ of the tracker (module doc) on ``frames`` frames of
    ``motion`` on ``body``/``shape`` with the ``tracker`` settings (default: the defaults)."""
    tracker = tracker or TrackerConfig()
    model = load_body(body, shape)
    with tempfile.TemporaryDirectory(prefix="swarmpose-bench-track-") as tmp:
        folder = Path(tmp) / "sequence"
        clip = load_motion_spec(motion, model, frames, 30.0)
        synthesize(model, clip, folder, SynthConfig(frames=frames), progress=False)
        config = ServiceConfig(source=str(folder), detector="simulated", body=body, shape=shape or "",
                               tracker=tracker, overlay=False)
        runs = []
        with progress_bar("bench track", repeats, enabled=progress, unit="run") as bar:
            for _ in range(repeats):
                runs.append(track_with_truth(config, frames))
                bar.update(1)
    evaluations = tracker.generations + 1
    fps = [r.summary.fps for r in runs]
    tracking_fps = [1000.0 * (len(r.timings) - 1) / sum(x["total"] for x in r.timings[1:]) if len(r.timings) > 1
                    else 0.0 for r in runs]
    splits = [_split(r.timings, evaluations) for r in runs]
    timings = runs[0].timings
    score = scores(runs[0])
    return {
        "body": model.name, "motion": motion, "frames": len(timings), "repeats": repeats,
        "particles": tracker.particles, "generations": tracker.generations, "tile": list(tracker.tile),
        "triangles": tracker.triangles, "fps": float(np.median(fps)), "tracking_fps": float(np.median(tracking_fps)),
        "fps_runs": fps, "first_frame_ms": float(np.median([r.timings[0]["total"] for r in runs])),
        "split_ms": {k: float(np.median([s[k] for s in splits])) for k in splits[0]} if splits[0] else {},
        "hypotheses_per_s": float(np.median(tracking_fps)) * tracker.particles * evaluations,
        "mpjpe_mm": score["mpjpe_mm"], "A100": score["A100"], "lost": score["lost"],
    }


def format_track_bench(result: dict) -> str:
    """A few human-readable lines for a :func:`bench_track` result."""
    s = result["split_ms"]
    lines = [
        f"tracker: {result['body']} ({result['triangles']} triangles), {result['motion']}, {result['frames']} frames, "
        f"p = {result['particles']}, g = {result['generations']}, tile {result['tile'][0]}x{result['tile'][1]}, "
        f"{result['repeats']} repeats (medians)",
        f"frames/s {result['fps']:.2f} overall, {result['tracking_fps']:.2f} after the first frame "
        f"({result['first_frame_ms']:.0f} ms); {result['hypotheses_per_s']:.0f} hypotheses/s while tracking",
        f"accuracy: delta {result['mpjpe_mm']:.1f} mm, A(100) {100 * result['A100']:.1f} %, "
        f"{result['lost']} frames lost",
    ]
    if s:
        lines.append(f"per generation (ms): launch (FK, depth and joint terms) {s['score']:.2f}, combining the "
                     f"terms {s['joint_term']:.2f}, PSO update {s['pso_update']:.2f}, total {s['total']:.2f}; "
                     f"outside the search {s['other_per_frame']:.1f} ms per frame")
    return "\n".join(lines)
