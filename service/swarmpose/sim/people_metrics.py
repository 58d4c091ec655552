"""Several people against their ground truth: per-person Δ after matching, identity switches,
MOTA and IDF1 (CLEAR MOT and ID metrics, computed by the ``motmetrics`` package).

Per frame, the true people and the tracked bodies are matched by the mean distance of their
evaluation joints (a pair farther apart than ``max_match_m`` is no match; motmetrics keeps a
match from the previous frame while it stays under that bound, then takes the cheapest
assignment). Δ of a true person is the mean joint error over the frames it was matched;
an identity switch is a true person matched to another id than before; a person is *lost*
on a frame where it is visible (``visible`` ≥ ``min_visible``) but unmatched.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

MAX_MATCH_M = 0.5
"""A tracked body whose joints lie farther than this (mean, m) from a true person's is not it."""
MIN_VISIBLE = 0.3
"""A true person counts (must be found) on frames where at least this share of it is visible."""


@dataclass(frozen=True)
class TruePerson:
    """One true person in one frame: id, joints (J, 3) m, share of its pixels visible 0..1."""

    id: int
    joints3d: np.ndarray
    visible: float = 1.0


def mean_joint_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance (m) between joints (J, 3) a and b over the joints both have; NaN when none."""
    d = np.linalg.norm(np.asarray(a, float) - np.asarray(b, float), axis=-1)
    ok = np.isfinite(d)
    return float(d[ok].mean()) if ok.any() else float("nan")


def longest_run(flags: list[bool]) -> int:
    """Length of the longest run of True in ``flags``."""
    best = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        best = max(best, run)
    return best


def score_people(truth: Mapping[int, list[TruePerson]], tracked: Mapping[int, Mapping[int, np.ndarray]],
                 max_match_m: float = MAX_MATCH_M, min_visible: float = MIN_VISIBLE) -> dict:
    """Multi-person scores over the frames of ``truth`` (frame -> true people).

    tracked: frame -> {body id: joints (J, 3) m} (a frame missing from it has no bodies).
    Returns ``mota``, ``idf1`` (None when undefined: no visible person), ``id_switches``,
    ``misses``, ``false_positives``, ``matches`` (counts over frames), ``per_person`` ({true id:
    {mpjpe_mm, matched_frames, visible_frames, longest_lost_run, ids}}), ``mpjpe_mm`` (mean
    over matched pairs) and ``matched`` ({true id: {frame: body id}}). Only people visible
    enough count: a hidden person is neither a miss nor a match target, and a body within
    ``max_match_m`` of a hidden person is left out (following someone hidden is no error).
    """
    import motmetrics as mm

    acc = mm.MOTAccumulator(auto_id=False)
    errors: dict[int, list[float]] = {}
    lost: dict[int, list[bool]] = {}
    visible_frames: dict[int, int] = {}
    frames = sorted(truth)
    for f in frames:
        people = [p for p in truth[f] if p.visible >= min_visible]
        hidden = [p for p in truth[f] if p.visible < min_visible]
        # a body following a hidden person is neither a match (it need not be found) nor a false positive
        bodies = {i: j for i, j in tracked.get(f, {}).items()
                  if not any(mean_joint_distance(p.joints3d, j) <= max_match_m for p in hidden)}
        dist = np.array([[mean_joint_distance(p.joints3d, j) for j in bodies.values()] for p in people],
                        dtype=np.float64).reshape(len(people), len(bodies))
        dist[~(dist <= max_match_m)] = np.nan
        acc.update([p.id for p in people], list(bodies), dist, frameid=f)
        for p in people:
            visible_frames[p.id] = visible_frames.get(p.id, 0) + 1
    events = acc.mot_events
    matched: dict[int, dict[int, bool]] = {}
    ids: dict[int, set[int]] = {}
    for (f, _), row in events.iterrows():
        if row["Type"] not in ("MATCH", "SWITCH"):
            continue
        oid, hid = int(row["OId"]), int(row["HId"])
        person = next(p for p in truth[f] if p.id == oid)
        err = 1000.0 * np.linalg.norm(np.asarray(person.joints3d, float) - np.asarray(tracked[f][hid], float), axis=-1)
        errors.setdefault(oid, []).extend(err[np.isfinite(err)].tolist())
        matched.setdefault(oid, {})[f] = hid
        ids.setdefault(oid, set()).add(hid)
    for f in frames:
        for p in truth[f]:
            if p.visible >= min_visible:
                lost.setdefault(p.id, []).append(f not in matched.get(p.id, {}))
    summary = mm.metrics.create().compute(acc, metrics=["mota", "idf1", "num_switches", "num_misses",
                                                        "num_false_positives", "num_matches"], name="all")
    per_person = {
        pid: {"mpjpe_mm": float(np.mean(errors[pid])) if errors.get(pid) else None,
              "matched_frames": len(matched.get(pid, {})), "visible_frames": visible_frames[pid],
              "longest_lost_run": longest_run(lost.get(pid, [])), "ids": sorted(ids.get(pid, set()))}
        for pid in sorted(visible_frames)}
    all_errors = [e for v in errors.values() for e in v]
    value = summary.loc["all"]
    def finite(x) -> float | None:
        return float(x) if np.isfinite(x) else None

    return {"mota": finite(value["mota"]), "idf1": finite(value["idf1"]), "id_switches": int(value["num_switches"]),
            "misses": int(value["num_misses"]), "false_positives": int(value["num_false_positives"]),
            "matches": int(value["num_matches"]), "mpjpe_mm": float(np.mean(all_errors)) if all_errors else None,
            "frames": len(frames), "per_person": per_person, "matched": matched}
