"""Lift 2D joints to 3D (J^e) by robust sampling of the observed depth (paper §2.3.2).

A 2D keypoint lies on the image of the person, often near a silhouette edge (wrists,
elbows) or over a hole of the sensor. For each keypoint the depth is read in a window
whose size shrinks with distance (``window_m`` metres wide at the person's depth, at least
3 px): valid depths only; the nearest cluster (within ``cluster_m`` of the window's 20th
percentile) is the person in front of the background, and its median is the surface
depth. A joint centre lies inside the body, so the surface depth is pushed back along the
viewing ray by the joint's typical radius (:data:`JOINT_RADIUS`). A keypoint without any
valid depth in its window, or whose depth is more than ``max_spread_m`` from the median of
the others (it slipped onto the background), lifts to NaN (it keeps its 2D term).
"""

from __future__ import annotations

import time

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.joints import Joints2D
from swarmpose.tracking.result import BodyResult

JOINT_RADIUS: dict[str, float] = {
    "head": 0.09, "nose": 0.0, "left_eye": 0.0, "right_eye": 0.0, "left_ear": 0.02, "right_ear": 0.02,
    "neck": 0.05, "left_shoulder": 0.05, "right_shoulder": 0.05, "left_elbow": 0.035, "right_elbow": 0.035,
    "left_wrist": 0.025, "right_wrist": 0.025, "left_hip": 0.07, "right_hip": 0.07, "mid_hip": 0.09,
    "left_knee": 0.045, "right_knee": 0.045, "left_ankle": 0.035, "right_ankle": 0.035,
    "left_heel": 0.0, "right_heel": 0.0, "left_toe": 0.0, "right_toe": 0.0,
}
"""Depth (m) of each joint centre behind the body surface a camera sees in front of it."""
LIFT_WINDOW_M = 0.06
"""Width (m at the person's typical depth) of the window a keypoint's depth is read in."""


def sample_surface_depth(depth: np.ndarray, u: float, v: float, window_px: int, cluster_m: float = 0.10) -> float:
    """Robust surface depth (m) around pixel (u, v): the median of the nearest depth cluster
    in a ``window_px`` square window; NaN when the window holds no valid depth.

    depth: (H, W) float m, 0 = invalid.
    """
    h, w = depth.shape
    half = max(1, window_px // 2)
    iu, iv = int(round(u)), int(round(v))
    if not (0 <= iu < w and 0 <= iv < h):
        return float("nan")
    patch = depth[max(0, iv - half):iv + half + 1, max(0, iu - half):iu + half + 1]
    vals = np.sort(patch[np.isfinite(patch) & (patch > 0)])
    n = vals.size
    if n == 0:
        return float("nan")
    at = 0.2 * (n - 1)  # the 20th percentile, interpolated between the two values around it as numpy does
    below = int(at)
    t, a, b = at - below, vals[below], vals[min(below + 1, n - 1)]
    front = b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t
    near = vals[:np.searchsorted(vals, front + cluster_m, side="right")]  # sorted: the nearest cluster
    half_n = near.size // 2
    return float(near[half_n] if near.size % 2 else (near[half_n - 1] + near[half_n]) / 2)


def median_depth(depth: np.ndarray, stride: int = 2) -> float | None:
    """The median (m) of a depth image's valid pixels (finite, > 0), read on every ``stride``-th row and
    column (a quarter of a frame's pixels at 2: a window's size needs no more); None when it has none."""
    sample = depth[::stride, ::stride]
    valid = sample[np.isfinite(sample) & (sample > 0)]
    if not valid.size:  # the valid pixels may all lie between the ones read
        valid = depth[np.isfinite(depth) & (depth > 0)]
    return float(np.median(valid)) if valid.size else None


def lift_keypoints(depth: np.ndarray, intrinsics: Intrinsics, points: dict[str, tuple[float, float, float]],
                   window_m: float = LIFT_WINDOW_M, max_spread_m: float = 0.7,
                   typical_depth: float | None = None) -> dict[str, np.ndarray]:
    """J^e: body point -> (3,) camera-frame position (m) or NaNs, for 2D points {name: (x, y, score)}.

    A lift more than ``max_spread_m`` in depth from the median of the lifts (with at least
    three) is dropped: its keypoint slipped off the silhouette onto the background.

    depth: (H, W) float m, 0 = invalid, at the intrinsics' size; typical_depth: the depth (m) at
    which the window is ``window_m`` wide (None: the median of ``depth``'s valid pixels).
    """
    out: dict[str, np.ndarray] = {}
    if not points:
        return out
    if typical_depth is None:
        typical_depth = median_depth(depth) or 3.0
    for name, (x, y, _score) in points.items():
        window = max(3, int(round(window_m * intrinsics.fx / typical_depth)))
        z = sample_surface_depth(depth, x, y, window)
        if not np.isfinite(z):
            out[name] = np.full(3, np.nan)
            continue
        ray = np.array([(x - intrinsics.cx) / intrinsics.fx, (y - intrinsics.cy) / intrinsics.fy, 1.0])
        surface = ray * z
        out[name] = surface + ray / np.linalg.norm(ray) * JOINT_RADIUS.get(name, 0.0)
    depths = np.array([p[2] for p in out.values() if np.isfinite(p[2])])
    if depths.size >= 3:  # a keypoint that slipped off the body reads the background: drop it
        centre = float(np.median(depths))
        for name, p in out.items():
            if np.isfinite(p[2]) and abs(p[2] - centre) > max_spread_m:
                out[name] = np.full(3, np.nan)
    return out


def lift_detection(depth: np.ndarray, intrinsics: Intrinsics, joints: Joints2D, min_score: float = 0.3
                   ) -> dict[str, np.ndarray]:
    """J^e of a detection's body points with score >= ``min_score`` (see :func:`lift_keypoints`)."""
    points = {k: v for k, v in joints.by_point().items() if v[2] >= min_score}
    return lift_keypoints(depth, intrinsics, points)


def lift_eval_joints(depth: np.ndarray, intrinsics: Intrinsics, joints: Joints2D | None, min_score: float
                     ) -> np.ndarray:
    """The ``lift`` baseline: J^e of the evaluation joints (14, 3) m (NaN where unknown).

    ``head`` lifts the mean of the detected ears (else eyes, else the nose) with the head's
    radius; ``neck`` is the detected neck, else the mean of the lifted shoulders.
    """
    if joints is None:
        return np.full((len(EVAL_JOINTS), 3), np.nan)
    pts = {k: v for k, v in joints.by_point().items() if v[2] >= min_score}
    wanted = {k: v for k, v in pts.items() if k in EVAL_JOINTS}
    for group in (("left_ear", "right_ear"), ("left_eye", "right_eye"), ("nose",)):
        found = [pts[g] for g in group if g in pts]
        if found and "head" not in wanted:
            wanted["head"] = tuple(np.mean(found, axis=0))
    lifted = lift_keypoints(depth, intrinsics, wanted)
    if "neck" not in lifted and "left_shoulder" in lifted and "right_shoulder" in lifted:
        lifted["neck"] = (lifted["left_shoulder"] + lifted["right_shoulder"]) / 2.0
    return np.array([lifted.get(j, np.full(3, np.nan)) for j in EVAL_JOINTS])


def lifted_body(body_id: int, depth: np.ndarray, intrinsics: Intrinsics, joints: Joints2D | None, min_score: float,
                started: float) -> BodyResult:
    """The ``lift`` mode's result for one frame: J^e of the evaluation joints as the answer, no model
    (state lost when no joint lifts); ``started``: the frame's ``time.perf_counter()`` at its start."""
    j3 = lift_eval_joints(depth, intrinsics, joints, min_score)
    ok = np.all(np.isfinite(j3), axis=1)
    j2 = intrinsics.project(np.where(np.isfinite(j3), j3, 1.0))
    j2[~ok] = np.nan
    state, reason = ("tracking", "") if ok.any() else ("lost", "no joints detected with depth")
    return BodyResult(body_id, state, reason, None, j3, j2, ok.astype(float), {},
                      {"total": 1000 * (time.perf_counter() - started)}, joints)
