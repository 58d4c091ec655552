"""``swarmpose bench utdmhad``: the tracker on real Kinect data, UTD-MHAD subjects s1–s3.

For every depth file of ``rgbd/utd_mhad/depth`` (27 actions x 3 subjects; every trial
there, and the assets hold trial 1) and every
requested variant (mode x detector x shape), track the sequence (its first ``frames``) with
the ``eval`` defaults unless told otherwise, and score it against the Kinect SDK skeleton
(:mod:`swarmpose.sources.utdmhad`):

* ``mpjpe_mm`` Δ over the 14 evaluation joints against the mapped Kinect joints, as is;
* ``mpjpe_offset_mm`` Δ after subtracting, per joint, the mean difference (estimate −
  Kinect, camera frame, m) measured on the *other two subjects* with the same variant
  (leave-one-subject-out, over the sequences of this run), which removes the constant part
  of the two skeletons' different joint definitions (Kinect hips sit higher and wider, its
  shoulders lower) but not errors that change with the pose — the subjects all face the
  camera, so a camera-frame offset is a body-frame offset here;
* ``visible_mm`` / ``hidden_mm``: Δ over the joints the Kinect's depth shows and over those it
  hides (:mod:`swarmpose.sim.visibility`; a joint the body itself covers counts as hidden);
* ``A100``, lost frames, and the detector's median 2D error (px) on the limbs' joints.

Detectors: ``simulated`` (the noise model applied to the projected Kinect skeleton; no face
keypoints) and ``movenet`` / ``blazepose`` run on the depth shaded as a surface (there is no
colour). Shapes: ``default`` (the body's default) and ``measured`` (the subject's height:
the median over the subject's sequences of the height measured on their first frame's
depth, :func:`~swarmpose.sources.utdmhad.measured_height`; a median, because a few actions
begin seated).

With ``seeds`` > 1 every (sequence, variant) is tracked once per PSO seed (0, 1, ...; seed 0's
files keep their names, seed s's end in ``-seed{s}``, and its record and settings carry
``seed``), since a single sequence's Δ varies with the seed. The table and
summary average over every record of a variant; the per-joint offsets of a subject are learnt
on the other subjects' records of all seeds.

Each (sequence, variant, seed) is one JSON record in ``OUT/results/`` with the per-frame
estimates in a ``.npz`` beside it, both written whole or not at all: an interrupted run
resumes. A record is reused when its frames, tracker settings and skeleton lag match (a
record without ``lag_frames`` was scored against the files' own pairing, lag 0); after a
change to the tracker, use a fresh ``--out``.

The skeleton is compared in time with the depth: ``lag_frames`` (default
:data:`~swarmpose.sources.utdmhad_sync.DEPTH_LAG_FRAMES`, measured on the data by
:mod:`swarmpose.sources.utdmhad_sync`; ``--lag 0`` the files' pairing) for the ground truth and
the simulated detector's keypoints alike. The lag is not part of a record's file name: give each
lag its own ``--out``.
"""

from __future__ import annotations

import os
import re
import zipfile
import zlib
from functools import cache
from pathlib import Path

import numpy as np

from swarmpose.bench.accuracy import scores, track_with_truth
from swarmpose.bench.detect import find_assets
from swarmpose.bench.matrix import DETECTORS, MODES
from swarmpose.bench.store import mode_settings, read_record, seeded, tracker_settings, write_record
from swarmpose.bench.utdmhad_names import ACTIONS, SHAPES, SUBJECTS
from swarmpose.core.errors import ConfigError
from swarmpose.core.progress import progress_bar
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.sim.evaluate import joint_errors, summarise
from swarmpose.sources.utdmhad import UtdMhadSource, measured_height
from swarmpose.sources.utdmhad_sync import DEPTH_LAG_FRAMES, check_lag
from swarmpose.tracking.config import TrackerConfig

FOLDER = "rgbd/utd_mhad/depth"
_NAME = re.compile(r"^a(\d+)_(s\d+)_t\d+_depth\.mat$")


def sequences(assets: Path, subjects: tuple[str, ...] = SUBJECTS, actions: tuple[int, ...] = ()) -> list[Path]:
    """The depth files of ``subjects`` (and ``actions``; empty: all), by action then subject;
    ConfigError when there are none."""
    folder = assets / FOLDER
    named = [(int(m.group(1)), p.name, p) for p in folder.glob("*_depth.mat") if (m := _NAME.match(p.name))
             and m.group(2) in subjects and (not actions or int(m.group(1)) in actions)]
    found = [p for _, _, p in sorted(named)]
    if not found:
        raise ConfigError(f"no UTD-MHAD depth files of subjects {', '.join(subjects)}"
                          f"{' and actions ' + str(list(actions)) if actions else ''} in {folder}")
    return found


def variant_name(mode: str, detector: str, shape: str) -> str:
    """``mode-detector-shape``: a variant's name in file names and summaries."""
    return f"{mode}-{detector}-{shape}"


@cache
def subject_height(folder: Path, subject: str) -> float:
    """A UTD-MHAD subject's height (m): the median over the subject's depth files in ``folder``
    of :func:`measured_height` on their first frame."""
    heights = []
    for path in sorted(folder.glob(f"*_{subject}_t*_depth.mat")):
        with UtdMhadSource(path) as source:
            heights.append(measured_height(source.depth[0], source.intrinsics))
    if not heights:
        raise ConfigError(f"no UTD-MHAD depth files of subject {subject} in {folder}")
    return float(np.median(heights))


def track_sequence(path: Path, mode: str, detector: str, shape: str, assets: Path, tracker: dict,
                   frames: int, lag_frames: float = DEPTH_LAG_FRAMES) -> tuple[dict, np.ndarray, np.ndarray]:
    """(record, estimates (F, J, 3), truth (F, J, 3)) of one sequence in one variant, the
    skeleton taken ``lag_frames`` behind the depth (the source's ``?lag=``)."""
    spec = DETECTORS[detector].format(assets=assets)
    match = _NAME.match(path.name)
    shape_spec = ""
    height = None
    if shape == "measured":
        height = subject_height(path.parent, match.group(2))
        shape_spec = f"height={height:.3f}"
    config = ServiceConfig(source=f"utdmhad:{path}?lag={float(lag_frames)!r}", detector=spec, shape=shape_spec,
                           tracker=TrackerConfig(mode=mode, **tracker), overlay=False)
    run = track_with_truth(config, frames)
    record = {"sequence": path.name.removesuffix("_depth.mat"), "action": int(match.group(1)),
              "subject": match.group(2), "mode": mode, "detector": detector, "shape": shape, "height_m": height,
              "requested_frames": frames, "lag_frames": lag_frames, **scores(run), **tracker}
    return record, run.estimates, run.truth


def variant_settings(tracker: dict, mode: str, shape: str) -> dict:
    """The tracker settings a variant's record is made and resumed with: ``auto_height`` on unless
    ``tracker`` turns it off, and off where it does nothing (a given shape, the lift mode), so that
    records made before the setting existed still match there; ``arm_proposals`` as
    :func:`~swarmpose.bench.store.mode_settings` has it."""
    applies = tracker.get("auto_height", True) and shape == "default" and mode != "lift"
    return {**mode_settings(tracker, mode), "auto_height": bool(applies)}


def run_utdmhad(out: Path, *, modes: tuple[str, ...] = MODES, detectors: tuple[str, ...] = ("simulated",),
                shapes: tuple[str, ...] = ("default",), frames: int = 0, tracker: dict | None = None,
                subjects: tuple[str, ...] = SUBJECTS, actions: tuple[int, ...] = (),
                assets: str | Path | None = None, lag_frames: float = DEPTH_LAG_FRAMES,
                progress: bool = True, seeds: int = 1) -> list[dict]:
    """Every (sequence, variant, seed) record, computed or read back from ``out/results``, with
    ``mpjpe_offset_mm`` filled in (see the module doc); the skeleton ``lag_frames`` behind the
    depth; ``seeds`` PSO seeds per sequence and variant, 0 .. seeds - 1."""
    for name, given, allowed in (("mode", modes, MODES), ("detector", detectors, tuple(DETECTORS)),
                                 ("shape", shapes, SHAPES)):
        bad = [g for g in given if g not in allowed]
        if bad:
            raise ConfigError(f"unknown {name} {bad[0]!r}; choose from {', '.join(allowed)}")
    if frames < 0:
        raise ConfigError(f"--frames must be 0 (all) or more, got {frames}")
    if seeds < 1:
        raise ConfigError(f"--seeds must be at least 1, got {seeds}")
    lag_frames = check_lag(lag_frames, "--lag")
    root = find_assets(assets).resolve()
    tracker = tracker_settings(tracker)
    results = Path(out) / "results"
    results.mkdir(parents=True, exist_ok=True)
    todo = [(path, m, d, s, seed) for seed in range(seeds) for path in sequences(root, subjects, actions)
            for m in modes for d in detectors for s in shapes]
    records, arrays = [], []
    with progress_bar("bench utdmhad", len(todo), enabled=progress, unit="sequence") as bar:
        for path, mode, detector, shape, seed in todo:
            settings, suffix = seeded(variant_settings(tracker, mode, shape), seed)
            stem = f"{path.name.removesuffix('_depth.mat')}-{variant_name(mode, detector, shape)}{suffix}"
            stored = _read(results / stem, frames, settings, lag_frames)
            if stored is None:
                record, estimates, truth = track_sequence(path, mode, detector, shape, root, settings, frames,
                                                          lag_frames)
                tmp = results / f"{stem}.tmp.npz"
                np.savez(tmp, estimates=estimates, truth=truth)
                os.replace(tmp, results / f"{stem}.npz")
                write_record(results / f"{stem}.json", record)
                stored = record, estimates, truth
            records.append(stored[0])
            arrays.append(stored[1:])
            bar.update(1)
    add_offset_scores(records, arrays)
    return records


def _read(stem: Path, frames: int, tracker: dict, lag_frames: float) -> tuple[dict, np.ndarray, np.ndarray] | None:
    """(record, estimates, truth) stored under ``stem`` (.json, .npz) for these frames, tracker
    settings and skeleton lag; None when absent, made otherwise, or unreadable."""
    record = read_record(stem.with_suffix(".json"), {"requested_frames": frames, "lag_frames": lag_frames, **tracker})
    if record is None:
        return None
    try:
        with np.load(stem.with_suffix(".npz")) as data:
            return record, data["estimates"], data["truth"]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
        return None


def add_offset_scores(records: list[dict], arrays: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Fill ``mpjpe_offset_mm`` of each record: Δ after the per-joint offset of the other subjects (same variant)."""
    def variant(r: dict) -> tuple:
        return r["mode"], r["detector"], r["shape"]

    offsets: dict[tuple, np.ndarray | None] = {}  # (variant, subject left out) -> (J, 3) m
    for record, (estimates, truth) in zip(records, arrays):
        key = (variant(record), record["subject"])
        if key not in offsets:
            others = [e - t for r, (e, t) in zip(records, arrays)
                      if variant(r) == key[0] and r["subject"] != key[1]]
            if others:
                diff = np.concatenate(others)  # (frames, J, 3), NaN where a body was lost
                seen = np.isfinite(diff)
                offsets[key] = np.where(seen, diff, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)  # 0: unseen
            else:
                offsets[key] = None
        offset = offsets[key]
        record["mpjpe_offset_mm"] = (None if offset is None
                                     else summarise(joint_errors(estimates - offset, truth))["mpjpe_mm"])


def format_table(records: list[dict]) -> str:
    """Markdown: per action, mean Δ (offset-corrected Δ) of each variant over the subjects; then all actions."""
    variants = sorted({(r["mode"], r["detector"], r["shape"]) for r in records},
                      key=lambda v: (MODES.index(v[0]), v[1], v[2]))
    head = ["action"] + [f"{m} {d} {s}" for m, d, s in variants]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cell(rows: list[dict]) -> str:
        raw = [r["mpjpe_mm"] for r in rows if r["mpjpe_mm"] is not None]
        fixed = [r["mpjpe_offset_mm"] for r in rows if r.get("mpjpe_offset_mm") is not None]
        if not raw:
            return "–"
        return f"{np.mean(raw):.0f}" + (f" ({np.mean(fixed):.0f})" if fixed else "")

    for action in sorted({r["action"] for r in records}):
        row = [f"a{action} {ACTIONS.get(action, '')}".strip()]
        row += [cell([r for r in records if r["action"] == action and (r["mode"], r["detector"], r["shape"]) == v])
                for v in variants]
        lines.append("| " + " | ".join(row) + " |")
    lines.append("| **all** | " + " | ".join(
        f"**{cell([r for r in records if (r['mode'], r['detector'], r['shape']) == v])}**" for v in variants) + " |")
    return "\n".join(lines) + "\n"


def summary(records: list[dict]) -> dict[str, dict[str, float | None]]:
    """Per variant: mean Δ and mean offset-corrected Δ over its records (every seed), Δ over the
    joints the depth shows and over those it hides (records made before the split left out),
    sequences, seeds, frames and lost frames (summed over the seeds), detector px."""
    out = {}
    for v in sorted({(r["mode"], r["detector"], r["shape"]) for r in records}):
        rows = [r for r in records if (r["mode"], r["detector"], r["shape"]) == v]

        def mean(key: str, rows=rows) -> float | None:
            values = [r[key] for r in rows if r.get(key) is not None]
            return float(np.mean(values)) if values else None

        out[variant_name(*v)] = {"mpjpe_mm": mean("mpjpe_mm"), "mpjpe_offset_mm": mean("mpjpe_offset_mm"),
                                 "visible_mm": mean("visible_mm"), "hidden_mm": mean("hidden_mm"),
                                 "sequences": len({r["sequence"] for r in rows}),
                                 "seeds": len({r.get("seed", 0) for r in rows}),
                                 "frames": int(sum(r["frames"] for r in rows)),
                                 "lost": int(sum(r["lost"] for r in rows)), "detector_px": mean("detector_px")}
    return out

