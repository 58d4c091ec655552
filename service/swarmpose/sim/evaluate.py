"""Evaluation metrics of the paper (§3.2): Δ (mean joint error) and the accuracy curve A(t).

Δ is the mean Euclidean distance (mm) between estimated and true joints over the
evaluation joints and frames that have an estimate; ``coverage`` is the share of
(frame, joint) pairs that have one. A(t) is the share of *all* (frame, joint) pairs whose
estimate lies within t mm, so a missing estimate counts as a miss and a tracker cannot
gain by answering less.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.errors import check_shape

THRESHOLDS_MM: tuple[int, ...] = tuple(range(20, 201, 20))


def joint_errors(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F, J) distances in mm between estimates and truth (F, J, 3) m; NaN where either is unknown."""
    estimates, truth = np.asarray(estimates, float), np.asarray(truth, float)
    check_shape("estimated joints", estimates, truth.shape)
    return 1000.0 * np.linalg.norm(estimates - truth, axis=-1)


def accuracy(errors_mm: np.ndarray, thresholds_mm=THRESHOLDS_MM) -> dict[int, float]:
    """A(t) for each threshold t (mm): share of all (frame, joint) pairs with error <= t (NaN = miss)."""
    errors_mm = np.asarray(errors_mm, float)
    total = errors_mm.size
    if total == 0:
        return {int(t): 0.0 for t in thresholds_mm}
    ok = np.isfinite(errors_mm)
    return {int(t): float(np.count_nonzero(ok & (np.where(ok, errors_mm, np.inf) <= t)) / total)
            for t in thresholds_mm}


def summarise(errors_mm: np.ndarray, thresholds_mm=THRESHOLDS_MM) -> dict:
    """``mpjpe_mm`` (Δ; None without any estimate), ``A`` (threshold -> share), ``coverage``,
    ``frames`` and ``per_joint_mm`` (J,) for errors (F, J) mm."""
    errors_mm = np.asarray(errors_mm, float)
    ok = np.isfinite(errors_mm)
    per_joint = [float(np.mean(col[np.isfinite(col)])) if np.isfinite(col).any() else None for col in errors_mm.T]
    return {
        "mpjpe_mm": float(np.mean(errors_mm[ok])) if ok.any() else None,
        "A": accuracy(errors_mm, thresholds_mm),
        "coverage": float(ok.mean()) if errors_mm.size else 0.0,
        "frames": int(errors_mm.shape[0]),
        "per_joint_mm": per_joint,
    }


def summarise_frames(ground_truth, frames, estimates: dict[int, np.ndarray]) -> dict:
    """:func:`summarise` over ``frames`` (frame numbers of ``ground_truth``, a
    :class:`~swarmpose.sources.groundtruth.GroundTruth`); ``estimates`` maps a frame to its (J, 3)
    joints in m. A frame without an estimate counts as a miss on every joint."""
    frames = list(frames)
    truth = ground_truth.joints3d[[ground_truth.row(f) for f in frames]]
    found = np.full_like(truth, np.nan)
    for k, frame in enumerate(frames):
        if frame in estimates:
            found[k] = estimates[frame]
    return summarise(joint_errors(found, truth))


def plot_accuracy(curves: dict[str, dict[int, float]], path, title: str = "") -> None:
    """Draw A(t) curves (label -> {t mm: share}) as the paper's figures do: t on x, % on y."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.0, 3.6), dpi=120)
    for label, curve in curves.items():
        ts = sorted(curve)
        ax.plot(ts, [100.0 * curve[t] for t in ts], marker="o", markersize=3, label=label)
    ax.set_xlabel("t (mm)")
    ax.set_ylabel("A(t) (%)")
    ax.set_ylim(0, 100)
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def torso_facing(joints: np.ndarray) -> np.ndarray:
    """(F, 3) unit forward direction of the torso of joints (F, J, 3) in ``EVAL_JOINTS`` order:
    the body's left axis (right to left shoulder plus right to left hip) crossed with its up
    axis (mid-hip to mid-shoulder), as :func:`swarmpose.tracking.init_pose.torso_pose` defines
    the body frame. NaN rows where a torso joint is missing."""
    j = {name: np.asarray(joints, float)[:, k] for k, name in enumerate(EVAL_JOINTS)}
    left = (j["left_shoulder"] - j["right_shoulder"]) + (j["left_hip"] - j["right_hip"])
    up = (j["left_shoulder"] + j["right_shoulder"] - j["left_hip"] - j["right_hip"]) / 2.0
    forward = np.cross(left, up)
    norm = np.linalg.norm(forward, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 1e-9, forward / norm, np.nan)


def facing_errors_deg(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F,) angle in degrees between the estimated and true torso facing (see
    :func:`torso_facing`) of joints (F, J, 3) m; NaN where either is unknown. A mirrored
    (front-for-back) fit is near 180°."""
    a, b = torso_facing(estimates), torso_facing(truth)
    cos = np.clip(np.sum(a * b, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))
