"""``swarmpose bench still``: the jitter of a person standing still, and the lag when they move (issue 53).

For every shape x camera yaw: a clip's frame held still (``CLIP?hold=AT:HOLD``,
:mod:`swarmpose.motion.hold`) for ``hold_s`` and then the clip going on for ``moving_s``, filmed
with the Kinect-like depth noise and the simulated detector's noise
(:mod:`swarmpose.sim.synth`, 3 m, 30 fps), into ``OUT/sequences/``. Each sequence is tracked
with every detector twice, with one-Euro and with centred smoothing; the search never sees the
smoothed poses, so each run's unsmoothed joints are the same track, published without smoothing
(``off_agree_mm`` says how far apart the two runs' unsmoothed joints are: 0 unless something fed a
smoothed pose back). Per (sequence, detector, smoothing), by :func:`swarmpose.sim.steadiness.still_report`:

* ``jitter_mm`` / ``jitter_max_mm`` / ``jitter_worst``: the per-joint standard deviation over
  the still frames, the first ``settle_s`` (the track's start) left out; mean and max over the
  joints, and the joint of the max;
* ``still_delta_mm``: Δ over those frames;
* ``lag_ms``: the median over the joints that move of the shift that best lines each one's
  tracked displacement up with the truth's over the first 0.5 s of motion (> 0: behind);
* ``onset_delta_mm`` / ``moving_delta_mm``: Δ over the first 0.3 s of motion / the rest of it.

Each (sequence, detector) is one JSON record in ``OUT/results/``, written when done, beside its
joints (``.npz``: the truth and each smoothing's joints, for another look): an interrupted run
resumes, and a record made with other settings is made again.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swarmpose.bench.accuracy import TrackedRun, track_with_truth
from swarmpose.bench.detect import find_assets
from swarmpose.bench.matrix import DETECTORS
from swarmpose.bench.still_plan import RUNS, SMOOTHINGS, StillPlan
from swarmpose.bench.store import read_record, render_whole, tracker_settings, write_record
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.progress import progress_bar
from swarmpose.motion.library import load_motion_spec
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.sim.steadiness import still_report
from swarmpose.sim.synth import SynthConfig, synthesize
from swarmpose.tracking.config import TrackerConfig


def sequence_name(shape: str, yaw: float) -> str:
    return f"still-{shape}-yaw{yaw:03.0f}"


def make_still_sequence(plan: StillPlan, shape: str, yaw: float, folder: Path, root: Path | None) -> Path:
    """``folder`` holding the held sequence of ``shape`` seen from ``yaw`` (rendered unless it is there,
    made from the same plan)."""
    description = {"still": {**plan.describe(), "shape": shape, "yaw": yaw}}
    meta = folder / "sequence.json"
    if meta.exists() and json.loads(meta.read_text()).get("still") == description["still"]:
        return folder
    body = load_body(body_spec(plan, root), shape)
    clip = plan.clip if plan.clip.startswith("builtin:") or root is None else str(root / plan.clip)
    motion = load_motion_spec(f"{clip}?hold={plan.at_s:g}:{plan.hold_s:g}", body, plan.frames, plan.fps)
    config = SynthConfig(frames=plan.frames, fps=plan.fps, camera_yaw_deg=float(yaw))
    return render_whole(folder, lambda tmp: synthesize(body, motion, tmp, config, description=description,
                                                       progress=False))


def body_spec(plan: StillPlan, root: Path | None) -> str:
    return f"makehuman:{root}/bodies/makehuman" if plan.body == "makehuman" else plan.body


def _rows(plan: StillPlan, runs: dict[str, TrackedRun]) -> list[dict]:
    """The three smoothings' reports of a sequence's two runs."""
    fps = plan.fps

    def report(estimates: np.ndarray, truth: np.ndarray) -> dict:
        return still_report(estimates, truth, plan.moves_at, fps, plan.settle, EVAL_JOINTS)

    first = runs[RUNS[0]]
    rows = [{"smoothing": "off", **report(first.unsmoothed, first.truth)}]
    rows += [{"smoothing": name, **report(run.estimates, run.truth)} for name, run in runs.items()]
    return rows


def track_still(plan: StillPlan, folder: Path, detector: str, shape: str, settings: dict, root: Path | None,
                joints_file: Path | None = None) -> dict:
    """The record of one sequence and detector: its rows (one per smoothing), the runs' fps and how far
    apart their unsmoothed joints are (mm). joints_file: where to keep the truth and each smoothing's
    joints (F, J, 3) m (``.npz``, keys ``truth``, ``off``, ``one-euro``, ``centred``), or None."""
    spec = DETECTORS[detector].format(assets=root)
    runs = {}
    for smoothing in RUNS:
        config = ServiceConfig(source=str(folder), detector=spec, body=body_spec(plan, root), shape=shape,
                               tracker=TrackerConfig(**settings, smoothing=smoothing), overlay=False)
        runs[smoothing] = track_with_truth(config, plan.frames)
    if joints_file is not None:
        np.savez_compressed(joints_file, truth=runs[RUNS[0]].truth, off=runs[RUNS[0]].unsmoothed,
                            **{name: run.estimates for name, run in runs.items()})
    a, b = (runs[r].unsmoothed for r in RUNS)
    gap = np.linalg.norm(a - b, axis=2)
    return {"rows": _rows(plan, runs), "fps": [runs[r].summary.fps for r in RUNS],
            "lost": [runs[r].lost for r in RUNS],
            "off_agree_mm": float(1000.0 * np.nanmax(gap)) if np.isfinite(gap).any() else None}


def run_still(out: Path, plan: StillPlan | None = None, tracker: dict | None = None,
              assets: str | Path | None = None, progress: bool = True) -> list[dict]:
    """Every (sequence, detector, smoothing) row of the module doc, tracked or read back from
    ``out/results``; each row also names its shape, yaw and detector. plan: None for the default."""
    plan = plan or StillPlan()
    plan.validate()
    root = find_assets(assets).resolve() if plan.needs_assets() else None
    settings = {k: v for k, v in tracker_settings(tracker).items() if k != "smoothing"}
    out = Path(out)
    (out / "results").mkdir(parents=True, exist_ok=True)
    todo = [(shape, yaw, det) for shape in plan.shapes for yaw in plan.yaws for det in plan.detectors]
    rows = []
    with progress_bar("bench still", len(todo), enabled=progress, unit="run") as bar:
        for shape, yaw, detector in todo:
            name = sequence_name(shape, yaw)
            expected = {"plan": json.loads(json.dumps(plan.describe())), **settings}
            path = out / "results" / f"{name}-{detector}.json"
            record = read_record(path, expected)
            if record is None:
                folder = make_still_sequence(plan, shape, yaw, out / "sequences" / name, root)
                record = {**expected, "sequence": name, "shape": shape, "yaw": yaw, "detector": detector,
                          **track_still(plan, folder, detector, shape, settings, root, path.with_suffix(".npz"))}
                write_record(path, record)
            cell = {k: record[k] for k in ("sequence", "shape", "yaw", "detector", "off_agree_mm")}
            rows += [{**cell, **row} for row in record["rows"]]
            bar.update(1)
    return rows


def _mean(rows: list[dict], key: str) -> float | None:
    values = [r[key] for r in rows if r[key] is not None]
    return float(np.mean(values)) if values else None


def summary(rows: list[dict]) -> list[dict]:
    """Per (detector, smoothing): the mean over sequences of the jitter (mm), still Δ, lag, onset and
    moving Δ, and the largest joint jitter with its joint and sequence."""
    out = []
    for detector in dict.fromkeys(r["detector"] for r in rows):
        for smoothing in SMOOTHINGS:
            group = [r for r in rows if r["detector"] == detector and r["smoothing"] == smoothing]
            if not group:
                continue
            known = [r for r in group if r["jitter_max_mm"] is not None]
            worst = max(known, key=lambda r: r["jitter_max_mm"]) if known else None
            out.append({"detector": detector, "smoothing": smoothing, "sequences": len(group),
                        **{k: _mean(group, k) for k in ("jitter_mm", "still_delta_mm", "lag_ms", "onset_delta_mm",
                                                "moving_delta_mm")},
                        "jitter_max_mm": None if worst is None else worst["jitter_max_mm"],
                        "jitter_worst": None if worst is None else f"{worst['jitter_worst']}, {worst['sequence']}"})
    return out
