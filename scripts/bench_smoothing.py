"""Jitter, lag and Δ of the One-Euro filter against no smoothing, on the accuracy benchmark's sequences.

The filter acts on the published poses only (the search starts from the unfiltered pose), so
one tracking run per sequence gives the unfiltered poses, and every filter setting is applied
to them afterwards; one setting is also tracked for real and must give the same poses (checked,
the script fails otherwise).

Per sequence and setting (EVAL_JOINTS, frames with a pose):

* Δ, mm: mean joint error against the ground truth;
* jitter, mm: RMS of the second difference of the joint *error* (estimate - truth) over
  consecutive tracked frames: the frame-to-frame shake the truth does not have;
* lag, ms: the shift s (0.1-frame steps, -5..+10 frames) of the truth that the estimate fits
  best, mean_t |est(t) - truth(t - s)| minimal; positive = the estimate trails.

Usage (shared assets beside the repository; MoveNet on the rendered colour)::

    .venv/bin/python scripts/bench_smoothing.py OUT_DIR [--frames 90] [--detector movenet]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from swarmpose.bench.accuracy import make_sequence, track_with_truth
from swarmpose.bench.detect import find_assets
from swarmpose.bench.matrix import DETECTORS, Sequence
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.one_euro import PoseFilter

SEQUENCES = (
    Sequence("walk", "male", 0, 1.2, 3.0),
    Sequence("walk", "female", 90, 2.2, 4.0),
    Sequence("dance", "male-heavy", 45, 1.2, 3.0),
    Sequence("jumping-jacks", "female-tall", 135, 2.2, 4.0),
)
SETTINGS = [(1.0, 0.5), (1.0, 2.0), (2.0, 2.0), (3.0, 5.0), (4.0, 10.0), (6.0, 10.0), (8.0, 20.0)]
"""(min cut-off Hz, beta) of the filters compared with no smoothing."""


def track(folder: Path, seq: Sequence, detector: str, assets: Path, tracker: TrackerConfig, frames: int):
    """Poses (F, 36) (NaN rows: lost), timestamps (F,) s and truth (F, J, 3) m of ``folder`` tracked."""
    config = ServiceConfig(source=str(folder), detector=DETECTORS[detector].format(assets=assets),
                           body=f"makehuman:{assets}/bodies/makehuman", shape=seq.shape, tracker=tracker,
                           overlay=False)
    run = track_with_truth(config, frames)
    return run.poses, run.times_s, run.truth


def filtered(poses: np.ndarray, times: np.ndarray, cutoff: float, beta: float) -> np.ndarray:
    """The poses a tracker with ``--smoothing one-euro`` publishes (the filter restarts after a lost frame)."""
    filt, out = PoseFilter(cutoff, beta), poses.copy()
    for i, (pose, t) in enumerate(zip(poses, times)):
        if np.isnan(pose[0]):
            filt.reset()
        else:
            out[i] = filt(pose, t)
    return out


def measures(joints: np.ndarray, truth: np.ndarray, fps: float) -> dict[str, float]:
    """Δ (mm), jitter (mm) and lag (ms) of estimated joints (F, J, 3) against the truth (see the module doc)."""
    ok = np.isfinite(joints[:, 0, 0])
    delta = float(np.mean(np.linalg.norm(joints[ok] - truth[ok], axis=-1))) * 1000
    err = joints - truth
    run = ok[:-2] & ok[1:-1] & ok[2:]
    second = err[2:] - 2 * err[1:-1] + err[:-2]
    jitter = float(np.sqrt(np.mean(np.sum(second[run] ** 2, axis=-1)))) * 1000
    frames = np.arange(len(truth), dtype=float)
    best_shift, best_err = 0.0, np.inf
    for shift in np.arange(-5.0, 10.01, 0.1):
        at = frames - shift
        inside = ok & (at >= 0) & (at <= len(truth) - 1)
        lo = np.clip(np.floor(at).astype(int), 0, len(truth) - 2)
        w = (at - lo)[:, None, None]
        moved = (1 - w) * truth[lo] + w * truth[lo + 1]
        e = float(np.mean(np.linalg.norm(joints[inside] - moved[inside], axis=-1)))
        if e < best_err:
            best_shift, best_err = float(shift), e
    return {"delta_mm": delta, "jitter_mm": jitter, "lag_ms": 1000 * best_shift / fps}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--detector", default="movenet", choices=sorted(DETECTORS))
    parser.add_argument("--no-check", action="store_true", help="skip the real smoothed run of the first sequence")
    args = parser.parse_args()
    assets = find_assets(None)
    tracker = TrackerConfig()
    rows = []
    for seq in SEQUENCES:
        folder = make_sequence(seq, args.out / seq.name, args.frames, assets)
        raw = args.out / f"{seq.name}-{args.detector}.npz"
        if raw.exists():  # the unfiltered run of an earlier call (tracking is seeded: it would repeat)
            saved = np.load(raw)
            poses, times, truth = saved["poses"], saved["times"], saved["truth"]
        else:
            poses, times, truth = track(folder, seq, args.detector, assets, tracker, args.frames)
            np.savez(raw, poses=poses, times=times, truth=truth)
        body = load_body(f"makehuman:{assets}/bodies/makehuman", seq.shape)
        body = body if len(body.triangles) <= tracker.triangles else body.tracking_lod(tracker.triangles)
        fps = 1.0 / float(np.median(np.diff(times)))
        lost = ~np.isfinite(poses[:, 0])
        runs = {"off": poses} | {f"one-euro {c:g} Hz, beta {b:g}": filtered(poses, times, c, b) for c, b in SETTINGS}
        for name, p in runs.items():
            joints = np.full(truth.shape, np.nan)
            joints[~lost] = body.posed_points(p[~lost], EVAL_JOINTS)
            rows.append({"sequence": seq.name, "setting": name, **measures(joints, truth, fps)})
            print(json.dumps(rows[-1]), flush=True)
        if seq is SEQUENCES[0] and not args.no_check:  # the offline filter must be what the tracker publishes
            c, b = SETTINGS[1]
            real, _, _ = track(folder, seq, args.detector, assets,
                                  replace(tracker, smoothing="one-euro", smoothing_cutoff_hz=c, smoothing_beta=b),
                                  args.frames)
            expected = runs[f"one-euro {c:g} Hz, beta {b:g}"]
            if not np.allclose(real, expected, atol=1e-9, equal_nan=True):
                raise SystemExit(f"the tracker's smoothed poses differ from the offline filter by "
                                 f"{np.nanmax(np.abs(real - expected)):.3g}")
            print("checked: tracking with --smoothing one-euro publishes the offline-filtered poses", flush=True)
    (args.out / "smoothing.json").write_text(json.dumps(rows, indent=1))
    names = list(dict.fromkeys(r["setting"] for r in rows))
    print("\n| setting | Δ mm | jitter mm | lag ms |\n|---|---|---|---|")
    for name in names:
        sel = [r for r in rows if r["setting"] == name]
        print(f"| {name} | {np.mean([r['delta_mm'] for r in sel]):.1f} | "
              f"{np.mean([r['jitter_mm'] for r in sel]):.2f} | {np.mean([r['lag_ms'] for r in sel]):.0f} |")


if __name__ == "__main__":
    main()
