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
* ``flipped`` frames (the torso facing more than 90° off), ``sides_swapped`` frames (the
  estimate's left/right torso joints fit the truth better exchanged), ``flips`` and their
  ``recovery_mean_s`` / ``recovery_max_s`` (to the first right frame; ``unrecovered`` 1 when the
  last flip lasted to the end), see :mod:`.flip_metrics`,
* ``visible_mm`` and ``hidden_mm``: Δ over the joints the depth shows and over those it hides
  (self-occlusion, another person, a prop), and ``hidden_share`` (see :mod:`swarmpose.sim.visibility`),
* ``fps`` of detection + tracking.

Each (cell, mode) is one JSON file in ``OUT/results/``, written when it is done: an
interrupted run resumes where it stopped. :func:`run_matrix` returns every record.

With ``seeds`` > 1 every (cell, mode) is tracked once per tracker seed (0, 1, ...; seed 0's
file keeps its name, seed s's ends in ``-seed{s}``): a single cell's Δ varies widely with the
seed, so a per-cell goal is judged on the mean over seeds (:func:`mean_over_seeds`).
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from functools import lru_cache, partial
from pathlib import Path

import numpy as np

from swarmpose.bench.detect import find_assets
from swarmpose.bench.flip_metrics import flip_metrics
from swarmpose.bench.hard_motions import FPS, HARD_MOTIONS, segment_frames
from swarmpose.bench.matrix import DETECTORS, MODES, MOTIONS, Cell, Sequence, cells
from swarmpose.bench.store import mode_settings, read_record, render_whole, seeded, tracker_settings, write_record
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
from swarmpose.sim.props import parse_prop_spec, placed_spec
from swarmpose.sim.scene import PersonSpec, load_people
from swarmpose.sim.synth import SynthConfig, place_scene, synthesize, synthesize_people
from swarmpose.sim.visibility import hidden_joints, split_errors_mm
from swarmpose.sources.base import Frame
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
    """``folder`` holding ``frames`` frames of ``seq`` (rendered unless already there, complete);
    a hard motion's from its segment's start, turned to face the camera at yaw 0 (:mod:`.hard_motions`)."""
    gt = folder / "groundtruth.jsonl"
    if gt.exists() and sum(1 for _ in gt.open()) >= frames:
        return folder
    config = synth_config(seq, frames)

    def render(tmp: Path) -> None:
        if seq.motion in HARD_MOTIONS:
            film_segment(seq, tmp, config, assets)
        else:
            body = subject(str(assets), seq.shape)
            motion = load_motion_spec(str(assets / MOTIONS[seq.motion]), body, frames, FPS)
            synthesize(body, motion, tmp, config, description={"benchmark": asdict(seq)}, progress=False)

    return render_whole(folder, render)


def synth_config(seq: Sequence, frames: int) -> SynthConfig:
    """How ``seq`` is filmed: ``frames`` frames at 30 fps from its camera, with its props
    (``synth --prop`` specs, :func:`swarmpose.sim.props.parse_prop_spec`)."""
    props = tuple(parse_prop_spec(p, f"sequence {seq.name}: prop") for p in seq.props)
    return SynthConfig(frames=frames, fps=FPS, camera_yaw_deg=float(seq.yaw_deg), camera_height=seq.camera_height,
                       camera_distance=seq.camera_distance, props=props)


def film_segment(seq: Sequence, out: Path, config: SynthConfig, assets: Path) -> None:
    """Render ``seq``'s hard motion into ``out``: its clip from the segment's start (the scene
    spec's ``start``), turned about the vertical (its ``yaw``) so that the pelvis faces the
    camera of yaw 0 at the first frame. Its props (a stool) are placed over the whole segment, so
    that they stand where the subject sits whatever part of it is filmed."""
    clip = HARD_MOTIONS[seq.motion]
    spec = PersonSpec(f"makehuman:{assets}/bodies/makehuman", seq.shape, str(assets / clip.clip), start_s=clip.start_s)
    person = load_people([spec], clip.frames if config.props else config.frames, config.fps)[0]
    forward = person.motion.root_rotation[0][:, 2]  # the pelvis's forward axis in the clip's world frame
    facing = float(np.degrees(np.arctan2(forward[0], forward[2])))
    person = replace(person, spec=replace(spec, yaw_deg=-facing))
    if config.props:
        whole = place_scene([person], replace(config, frames=clip.frames))
        config = replace(config, props=tuple(placed_spec(prop) for prop in whole.props))
    synthesize_people([person], out, config, progress=False,
                      description={"benchmark": asdict(seq), "segment": {**asdict(clip), "turned_deg": -facing}})


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
    (F, J, 3) m (the estimates themselves when nothing is smoothed), and which true joints the
    depth hides (F, J) bool (:func:`~swarmpose.sim.visibility.hidden_joints`)."""

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
    hidden: np.ndarray | None = None


def _seen(source, truth_of, hidden: dict[int, np.ndarray]):
    """``source``'s items unchanged; each frame's hidden true joints noted in ``hidden`` (index -> (J,) bool)."""
    for item in source:
        if isinstance(item, Frame):
            try:
                joints = truth_of.joints3d[truth_of.row(item.index)]
            except KeyError:  # a frame without truth: no joint to judge
                joints = np.full((len(EVAL_JOINTS), 3), np.nan)
            hidden[item.index] = hidden_joints(item.depth, item.intrinsics, joints)
        yield item


def track_with_truth(config: ServiceConfig, frames: int = 0) -> TrackedRun:
    """Track ``config``'s source (its first ``frames``; 0 = all) and collect estimates beside its ground truth."""
    summary = RunSummary()
    estimates, detections, timings, done, poses, times, unsmoothed, lost = [], [], [], [], [], [], [], 0
    with ExitStack() as stack:
        parts = open_parts(config, stack, score=False, need_ground_truth=True)
        truth_of = parts.source.ground_truth
        intrinsics = parts.source.intrinsics
        hidden: dict[int, np.ndarray] = {}
        for result in results(_seen(parts.source, truth_of, hidden), parts.pipeline, frames, summary):
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
                      np.asarray(times, float), np.asarray(unsmoothed, float).reshape(-1, len(EVAL_JOINTS), 3),
                      np.asarray([hidden.get(f, np.ones(len(EVAL_JOINTS), bool)) for f in done],
                                 bool).reshape(-1, len(EVAL_JOINTS)))


def scores(run: TrackedRun) -> dict:
    """Δ, A(100), lost frames, torso facing and the detector's 2D errors of a tracked run (the module doc's fields)."""
    errors = joint_errors(run.estimates, run.truth)
    score = summarise(errors)
    facing = facing_errors_deg(run.estimates, run.truth)
    known = np.isfinite(facing)
    truth2d = run.intrinsics.project(run.truth.reshape(-1, 3)).reshape(*run.truth.shape[:2], 2)
    px, swapped = detector_errors(run.detections, truth2d)
    return {"frames": len(run.estimates), "mpjpe_mm": score["mpjpe_mm"], "A100": score["A"][100], "lost": run.lost,
            "facing_deg": float(np.mean(facing[known])) if known.any() else None,
            "facing_ok": float(np.mean(facing[known] <= FACING_OK_DEG)) if known.any() else 0.0,
            "detector_px": px, "swapped": swapped, "fps": run.summary.fps,
            **flip_metrics(run.estimates, run.truth, run.times_s),
            **(split_errors_mm(errors, run.hidden) if run.hidden is not None else {})}


def track_cell(cell: Cell, mode: str, folder: Path, assets: Path, tracker: dict, frames: int = 0) -> dict:
    """Track ``folder`` (its first ``frames``; 0 = all) in ``mode`` with the cell's detector;
    the record of the module doc."""
    spec = DETECTORS[cell.detector].format(assets=assets)
    config = ServiceConfig(source=str(folder), detector=spec, body=f"makehuman:{assets}/bodies/makehuman",
                           shape=cell.sequence.shape, tracker=TrackerConfig(mode=mode, **tracker), overlay=False)
    run = track_with_truth(config, frames)
    return {"cell": cell.name, "mode": mode, **asdict(cell.sequence), "props": list(cell.sequence.props),
            "detector": cell.detector, **scores(run), **tracker}


def run_matrix(out: Path, *, subset: str = "full", detectors: tuple[str, ...] | None = None,
               modes: tuple[str, ...] = MODES, frames: int = 40, tracker: dict | None = None,
               assets: str | Path | None = None, progress: bool = True, seeds: int = 1,
               motions: tuple[str, ...] | None = None) -> list[dict]:
    """Every (cell, mode, seed) record of the matrix (computed, or read back from ``out/results``);
    ``seeds`` tracker seeds per (cell, mode), 0 .. seeds - 1; ``motions`` limits the cells to those
    motions' sequences; ``frames`` per sequence (a hard motion's at most its segment's)."""
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
    todo = [(cell, mode, seed) for seed in range(seeds) for cell in cells(subset, detectors, motions)
            for mode in modes]
    records = []
    with progress_bar("bench accuracy", len(todo), enabled=progress, unit="run") as bar:
        for cell, mode, seed in todo:
            settings, suffix = seeded(mode_settings(tracker, mode), seed)
            path = out / "results" / f"{cell.name}-{mode}{suffix}.json"
            count = segment_frames(cell.sequence.motion, frames)
            record = read_record(path, {"frames": count, **settings})
            if record is None:
                folder = make_sequence(cell.sequence, out / "sequences" / cell.sequence.name, count, root)
                record = track_cell(cell, mode, folder, root, settings, count)
                write_record(path, record)
                log.info("%s %s seed %d: %.1f mm", cell.name, mode, seed, record["mpjpe_mm"] or float("nan"))
            records.append(record)
            bar.update(1)
    return records


AVERAGED = ("mpjpe_mm", "A100", "lost", "facing_deg", "facing_ok", "fps", "detector_px", "swapped", "visible_mm",
            "hidden_mm", "hidden_share")
"""The fields of a record :func:`mean_over_seeds` averages (the others are the same for every seed;
the detector's errors are not: it runs on a crop around the track)."""
FLIP_COUNTS = ("flipped", "sides_swapped", "flips", "unrecovered")
"""Flip fields (:mod:`.flip_metrics`) averaged over seeds; records made before them have none."""


def mean_over_seeds(records: list[dict]) -> list[dict]:
    """One record per (cell, mode): :data:`AVERAGED` fields averaged over its seeds (None where a
    seed had none; left out where no seed has the field), plus ``seeds`` (how many) and
    ``mpjpe_spread_mm`` (largest minus smallest Δ)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for record in records:
        groups.setdefault((record["cell"], record["mode"]), []).append(record)
    merged = []
    for group in groups.values():
        out = {k: v for k, v in group[0].items() if k != "seed"}
        for key in (k for k in AVERAGED if any(k in r for r in group)):  # older records lack the newer fields
            values = [r.get(key) for r in group]
            out[key] = None if any(v is None for v in values) else float(np.mean(values))
        if any("flips" in r for r in group):
            out.update(_flips_over_seeds(group))
        out["seeds"] = len(group)
        out["mpjpe_spread_mm"] = None if out["mpjpe_mm"] is None else float(np.ptp([r["mpjpe_mm"] for r in group]))
        merged.append(out)
    return merged


def _flips_over_seeds(group: list[dict]) -> dict:
    """The flip fields of one (cell, mode)'s seeds: counts averaged (None when a seed has none),
    the mean recovery over the seeds with a flip, the longest recovery of any."""
    out = {}
    for key in FLIP_COUNTS:
        values = [r.get(key) for r in group]
        out[key] = None if any(v is None for v in values) else float(np.mean(values))
    means = [r["recovery_mean_s"] for r in group if r.get("recovery_mean_s") is not None]
    longest = [r["recovery_max_s"] for r in group if r.get("recovery_max_s") is not None]
    out["recovery_mean_s"] = float(np.mean(means)) if means else None
    out["recovery_max_s"] = float(np.max(longest)) if longest else None
    return out
