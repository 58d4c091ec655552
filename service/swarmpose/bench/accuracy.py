"""``swarmpose bench accuracy``: the tracker over the benchmark matrix (see :mod:`.matrix`).

For every cell of the matrix and every mode: synthesise the cell's sequence once (MakeHuman
subject, CMU/other mocap clip, camera yaw/height/distance) into ``OUT/sequences/``, track it
with the subject's own shape, and score it against the ground truth:

* ``mpjpe_mm`` Δ and ``A100`` (share of joints within 100 mm, misses included),
* ``lost`` frames (no body, or the body's state *lost*),
* ``facing_deg`` the mean torso-facing error and ``facing_ok`` the share of frames within 30°
  (a front-for-back fit is near 180°),
* ``detector_px`` the detector's median 2D error on the limbs' joints against the true
  projections, and ``swapped`` the share of frames where its left/right torso labels fit the
  truth better swapped,
* ``fps`` of detection + tracking.

Each (cell, mode) is one JSON file in ``OUT/results/``, written when it is done: an
interrupted run resumes where it stopped. :func:`run_matrix` returns every record.

With ``seeds`` > 1 every (cell, mode) is tracked once per tracker seed (0, 1, ...; seed 0's
file keeps its name, seed s's ends in ``-seed{s}``): a single cell's Δ varies widely with the
seed, so a per-cell goal is judged on the mean over seeds (:func:`mean_over_seeds`).
"""

from __future__ import annotations

import logging
import shutil
from contextlib import ExitStack
from dataclasses import asdict, dataclass
from functools import lru_cache, partial
from pathlib import Path

import numpy as np

from swarmpose.bench.detect import find_assets
from swarmpose.bench.matrix import DETECTORS, MODES, MOTIONS, Cell, Sequence, cells
from swarmpose.bench.store import mode_settings, read_record, seeded, tracker_settings, write_record
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS, POSE_DIM
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.core.progress import progress_bar
from swarmpose.detect.joints import Joints2D
from swarmpose.motion.library import load_motion_spec
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.run import RunSummary, results
from swarmpose.pipeline.service import open_parts
from swarmpose.sim.evaluate import facing_errors_deg, joint_errors, summarise
from swarmpose.sim.synth import SynthConfig, synthesize
from swarmpose.tracking.config import TrackerConfig

log = logging.getLogger(__name__)

FACING_OK_DEG = 30.0
LIMB_JOINTS = tuple(j for j in EVAL_JOINTS if j not in ("head", "neck"))
PAIRS = (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"))


@lru_cache(maxsize=4)
def subject(assets: str, shape: str):
    """The MakeHuman subject of a shape preset (cached: loading takes seconds)."""
    return load_body(f"makehuman:{assets}/bodies/makehuman", shape)


def make_sequence(seq: Sequence, folder: Path, frames: int, assets: Path) -> Path:
    """``folder`` holding ``frames`` frames of ``seq`` (rendered unless already there, complete)."""
    gt = folder / "groundtruth.jsonl"
    if gt.exists() and sum(1 for _ in gt.open()) >= frames:
        return folder
    body = subject(str(assets), seq.shape)
    motion = load_motion_spec(str(assets / MOTIONS[seq.motion]), body, frames, 30.0)
    config = SynthConfig(frames=frames, camera_yaw_deg=float(seq.yaw_deg), camera_height=seq.camera_height,
                         camera_distance=seq.camera_distance)
    tmp = folder.with_name(folder.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)  # left by an interrupted run
    synthesize(body, motion, tmp, config, description={"benchmark": asdict(seq)}, progress=False)
    shutil.rmtree(folder, ignore_errors=True)  # too short for this run's --frames
    tmp.rename(folder)
    return folder


def _pixel_gap(found: dict, truth: np.ndarray, index: dict[str, int], detected: str, true: str) -> float:
    """Pixels between the detected keypoint ``detected`` and the true projection of joint ``true``."""
    return float(np.hypot(*(np.array(found[detected][:2]) - truth[index[true]])))


def detector_errors(detections: list, truth2d: np.ndarray) -> tuple[float | None, float | None]:
    """(median 2D error px over the limb joints, share of frames with left/right torso labels
    swapped) of ``detections`` (one Joints2D or None per frame) against ``truth2d`` (F, J, 2)."""
    index = {n: k for k, n in enumerate(EVAL_JOINTS)}
    errors, swaps, judged = [], 0, 0
    for det, truth in zip(detections, truth2d):
        if det is None:
            continue
        found = det.by_point(0.3)
        gap = partial(_pixel_gap, found, truth, index)
        errors += [gap(n, n) for n in LIMB_JOINTS if n in found]
        if all(n in found for pair in PAIRS for n in pair):
            judged += 1
            swaps += sum(gap(a, b) + gap(b, a) for a, b in PAIRS) < sum(gap(a, a) + gap(b, b) for a, b in PAIRS)
    return (float(np.median(errors)) if errors else None), (swaps / judged if judged else None)


@dataclass
class TrackedRun:
    """One source tracked against its ground truth: estimates and truth (F, J, 3) m in
    ``EVAL_JOINTS`` order (NaN rows where the body was lost), the detections (Joints2D or
    None per frame), lost frames, the run's summary, the camera and every frame's timings
    (ms, the frame message's ``timings_ms``), the published poses (F, 36) (NaN rows: lost), the
    frames' capture times (F,) s and the joints as the search found them before any smoothing
    (F, J, 3) m (the estimates themselves when nothing is smoothed)."""

    estimates: np.ndarray
    truth: np.ndarray
    detections: list[Joints2D | None]
    lost: int
    summary: RunSummary
    intrinsics: Intrinsics
    timings: list[dict[str, float]]
    poses: np.ndarray
    times_s: np.ndarray
    unsmoothed: np.ndarray


def track_with_truth(config: ServiceConfig, frames: int = 0) -> TrackedRun:
    """Track ``config``'s source (its first ``frames``; 0 = all) and collect estimates beside its ground truth."""
    summary = RunSummary()
    estimates, detections, timings, done, poses, times, unsmoothed, lost = [], [], [], [], [], [], [], 0
    with ExitStack() as stack:
        parts = open_parts(config, stack, score=False, need_ground_truth=True)
        truth_of = parts.source.ground_truth
        intrinsics = parts.source.intrinsics
        for result in results(parts.source, parts.pipeline, frames, summary):
            body = result.bodies[0] if result.bodies else None
            found = body is not None and body.state != "lost"
            lost += not found
            estimates.append(body.joints3d if found else np.full((len(EVAL_JOINTS), 3), np.nan))
            unsmoothed.append(body.found.joints3d if found else np.full((len(EVAL_JOINTS), 3), np.nan))
            poses.append(body.pose if found and body.pose is not None else np.full(POSE_DIM, np.nan))
            times.append(result.timestamp_ns * 1e-9)
            detections.append(body.detection if body is not None else None)
            timings.append(dict(result.timings_ms))
            done.append(result.index)
    truth = truth_of.joints3d[[truth_of.row(f) for f in done]]
    return TrackedRun(np.asarray(estimates, float).reshape(-1, len(EVAL_JOINTS), 3), truth, detections, lost,
                      summary, intrinsics, timings, np.asarray(poses, float).reshape(-1, POSE_DIM),
                      np.asarray(times, float), np.asarray(unsmoothed, float).reshape(-1, len(EVAL_JOINTS), 3))


def scores(run: TrackedRun) -> dict:
    """Δ, A(100), lost frames, torso facing and the detector's 2D errors of a tracked run (the module doc's fields)."""
    score = summarise(joint_errors(run.estimates, run.truth))
    facing = facing_errors_deg(run.estimates, run.truth)
    known = np.isfinite(facing)
    truth2d = run.intrinsics.project(run.truth.reshape(-1, 3)).reshape(*run.truth.shape[:2], 2)
    px, swapped = detector_errors(run.detections, truth2d)
    return {"frames": len(run.estimates), "mpjpe_mm": score["mpjpe_mm"], "A100": score["A"][100], "lost": run.lost,
            "facing_deg": float(np.mean(facing[known])) if known.any() else None,
            "facing_ok": float(np.mean(facing[known] <= FACING_OK_DEG)) if known.any() else 0.0,
            "detector_px": px, "swapped": swapped, "fps": run.summary.fps}


def track_cell(cell: Cell, mode: str, folder: Path, assets: Path, tracker: dict, frames: int = 0) -> dict:
    """Track ``folder`` (its first ``frames``; 0 = all) in ``mode`` with the cell's detector;
    the record of the module doc."""
    spec = DETECTORS[cell.detector].format(assets=assets)
    config = ServiceConfig(source=str(folder), detector=spec, body=f"makehuman:{assets}/bodies/makehuman",
                           shape=cell.sequence.shape, tracker=TrackerConfig(mode=mode, **tracker), overlay=False)
    run = track_with_truth(config, frames)
    return {"cell": cell.name, "mode": mode, **asdict(cell.sequence), "detector": cell.detector,
            **scores(run), **tracker}


def run_matrix(out: Path, *, subset: str = "full", detectors: tuple[str, ...] | None = None,
               modes: tuple[str, ...] = MODES, frames: int = 40, tracker: dict | None = None,
               assets: str | Path | None = None, progress: bool = True, seeds: int = 1) -> list[dict]:
    """Every (cell, mode, seed) record of the matrix (computed, or read back from ``out/results``);
    ``seeds`` tracker seeds per (cell, mode), 0 .. seeds - 1."""
    if frames < 2:
        raise ConfigError(f"--frames must be at least 2, got {frames}")
    if seeds < 1:
        raise ConfigError(f"--seeds must be at least 1, got {seeds}")
    bad = [m for m in modes if m not in MODES]
    if bad:
        raise ConfigError(f"unknown mode {bad[0]!r}; choose from {', '.join(MODES)}")
    root = find_assets(assets).resolve()
    tracker = tracker_settings(tracker)
    out = Path(out)
    (out / "results").mkdir(parents=True, exist_ok=True)
    todo = [(cell, mode, seed) for seed in range(seeds) for cell in cells(subset, detectors) for mode in modes]
    records = []
    with progress_bar("bench accuracy", len(todo), enabled=progress, unit="run") as bar:
        for cell, mode, seed in todo:
            settings, suffix = seeded(mode_settings(tracker, mode), seed)
            path = out / "results" / f"{cell.name}-{mode}{suffix}.json"
            record = read_record(path, {"frames": frames, **settings})
            if record is None:
                folder = make_sequence(cell.sequence, out / "sequences" / cell.sequence.name, frames, root)
                record = track_cell(cell, mode, folder, root, settings, frames)
                write_record(path, record)
                log.info("%s %s seed %d: %.1f mm", cell.name, mode, seed, record["mpjpe_mm"] or float("nan"))
            records.append(record)
            bar.update(1)
    return records


AVERAGED = ("mpjpe_mm", "A100", "lost", "facing_deg", "facing_ok", "fps", "detector_px", "swapped")
"""The fields of a record :func:`mean_over_seeds` averages (the others are the same for every seed;
the detector's errors are not: it runs on a crop around the track)."""


def mean_over_seeds(records: list[dict]) -> list[dict]:
    """One record per (cell, mode): :data:`AVERAGED` fields averaged over its seeds (None where a
    seed had none), plus ``seeds`` (how many) and ``mpjpe_spread_mm`` (largest minus smallest Δ)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for record in records:
        groups.setdefault((record["cell"], record["mode"]), []).append(record)
    merged = []
    for group in groups.values():
        out = {k: v for k, v in group[0].items() if k != "seed"}
        for key in AVERAGED:
            values = [r.get(key) for r in group]
            out[key] = None if any(v is None for v in values) else float(np.mean(values))
        out["seeds"] = len(group)
        out["mpjpe_spread_mm"] = None if out["mpjpe_mm"] is None else float(np.ptp([r["mpjpe_mm"] for r in group]))
        merged.append(out)
    return merged
