"""After the search: is the fit lost, and how much to trust each joint.

* **Lost** when the 2D joints are off by more than ``lost_joint_error`` of the person's size
  (weighted mean), or fewer than ``lost_depth_agreement`` of the model's rendered pixels
  agree with the depth within T, or there are neither joints nor depth to fit. Where other
  people's pixels were removed from the depth (several people), the 2D test is not applied while
  at least :data:`HIDDEN_TRUST_SEEN` of the model's pixels are observed and
  :data:`HIDDEN_TRUST_AGREEMENT` of those agree: the detection on
  a crop that others overlap is what is off then, and a person partly behind another whose fit
  the depth confirms would otherwise be judged lost and take frames to be found again.
* **Confidence** per evaluation joint, 0..1: the mean of a 2D agreement
  ``s·exp(−½(d/σ)²)`` (s = detection score, d = model–detection distance px, σ = 4 % of the
  person's size; only where the layout detects the joint) and a depth agreement
  ``exp(−½(Δz/5 cm)²)`` (Δz = rendered model depth − observed depth at the joint's pixel,
  nearest common pixel within one tile pixel); 0 when neither exists.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.detect.joints import Joints2D
from swarmpose.tracking.objective import JointTargets, Objective

HIDDEN_TRUST_AGREEMENT = 0.8
"""With other people's pixels removed, a fit whose observed pixels agree with the depth at least
this much is not judged lost on its 2D joints alone ..."""
HIDDEN_TRUST_SEEN = 0.5
"""... provided at least this share of its rendered pixels has an observation (a fit nearly all
behind others is judged on its joints as before)."""


def judge(objective: Objective, counts: dict[str, np.ndarray] | None, targets: JointTargets,
          parts: dict[str, float], state: str, lost_joint_error: float, lost_depth_agreement: float,
          observed_only: bool = False) -> tuple[str, str]:
    """(state, reason) of the chosen pose: ``state`` kept, or ``lost`` with why.

    counts: the scorer's ``rendered`` / ``both`` / ``close`` pixel counts of the chosen pose
    (None: no observed depth in the box); parts: its objective terms (E_J2D px);
    observed_only: the depth agreement counts only the model's pixels that have an
    observation (``both``), for a depth with other people's pixels removed: the model's
    parts behind them are hidden, not wrong; and the 2D test waits on a poor agreement
    (:data:`HIDDEN_TRUST_AGREEMENT`)."""
    agree, seen = None, 0.0
    if counts is not None and objective.weights.depth > 0:
        rendered = int(counts["both" if observed_only else "rendered"][0])
        agree = int(counts["close"][0]) / rendered if rendered else 0.0
        seen = int(counts["both"][0]) / max(int(counts["rendered"][0]), 1)
    if objective.uses_joints:
        size = targets.extent_px
        hidden_by_others = (observed_only and agree is not None and agree >= HIDDEN_TRUST_AGREEMENT
                            and seen >= HIDDEN_TRUST_SEEN)
        if size > 0 and parts["E_J2D"] > lost_joint_error * size and not hidden_by_others:
            return "lost", f"2D joints off by {parts['E_J2D']:.0f} px (person {size:.0f} px)"
    if agree is not None and agree < lost_depth_agreement:
        return "lost", f"only {100 * agree:.0f} % of the model's pixels agree with the depth"
    if not objective.uses_joints and not objective.has_depth:
        return "lost", "no joints and no depth to fit"
    return state, "" if objective.uses_joints else "no joints detected: depth only"


def confidence(objective: Objective, tile: np.ndarray | None, joints2d: np.ndarray, joints: Joints2D | None,
               targets: JointTargets, min_score: float) -> np.ndarray:
    """(14,) 0..1 per evaluation joint. tile: the chosen pose's rendered depth tile (TH, TW) m
    or None; joints2d: (14, 2) px of the chosen pose."""
    scores = np.full((len(EVAL_JOINTS), 2), np.nan)
    detected = joints.by_point(min_score) if joints is not None else {}
    sigma = max(0.04 * targets.extent_px, 4.0)
    for i, name in enumerate(EVAL_JOINTS):
        if name in detected:
            x, y, s = detected[name]
            d = float(np.hypot(joints2d[i, 0] - x, joints2d[i, 1] - y))
            scores[i, 0] = s * np.exp(-0.5 * (d / sigma) ** 2)
    tb, observed = objective.scorer.tile_box, objective.scorer.observed
    if tile is not None:
        tu = np.floor((joints2d[:, 0] - tb.u0 + 0.5) / tb.bw * tb.tw).astype(int)
        tv = np.floor((joints2d[:, 1] - tb.v0 + 0.5) / tb.bh * tb.th).astype(int)
        for i in range(len(EVAL_JOINTS)):
            if not (0 <= tu[i] < tb.tw and 0 <= tv[i] < tb.th):
                continue
            r = tile[max(tv[i] - 1, 0):tv[i] + 2, max(tu[i] - 1, 0):tu[i] + 2]
            o = observed[max(tv[i] - 1, 0):tv[i] + 2, max(tu[i] - 1, 0):tu[i] + 2]
            both = (r > 0) & (o > 0)
            if both.any():
                dz = float(np.min(np.abs(r[both] - o[both])))
                scores[i, 1] = np.exp(-0.5 * (dz / 0.05) ** 2)
    known = np.isfinite(scores)
    return np.where(known, scores, 0.0).sum(axis=1) / np.maximum(known.sum(axis=1), 1)
