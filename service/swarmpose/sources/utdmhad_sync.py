"""UTD-MHAD's skeleton and depth are not paired in time: the depth frame ``t`` shows the person
where the skeleton of frame ``t − 1.75`` puts them.

The lag is found from the data alone, without the tracker (:func:`depth_agreement_mm`,
``scripts/utdmhad_lag.py``): for each trial lag L, the skeleton at ``t − L`` (linear
interpolation between frames) is projected into depth frame ``t`` and its moving joints
(wrists, hands, elbows, knees, ankles) and head are compared with the depth under them; the
mean disagreement (each pixel's |depth − joint z| capped at :data:`CAP_M`) is least at
L = 1.75 frames. About 58 ms: at 2 m/s a fist is 12 cm from where the skeleton of the same
index says.

So :class:`~swarmpose.sources.utdmhad.UtdMhadSource` compares depth frame ``t`` with the
skeleton at ``t − DEPTH_LAG_FRAMES`` (:func:`synchronised`), for the ground truth and for the
simulated detector's keypoints alike (a detector run on the depth sees the person of the
depth's time). ``utdmhad:FILE?lag=0`` keeps the files' pairing. Why the files pair them so is
not known (the dataset's recording tool is not described).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError

DEPTH_LAG_FRAMES = 1.75
"""Frames by which UTD-MHAD's depth trails its skeleton (the measure of the module doc)."""

MAX_LAG_FRAMES = 10.0
"""The largest lag accepted (the depth never leads the skeleton: no negative lags)."""

AGREEMENT_JOINTS: tuple[str, ...] = ("head", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand",
                                     "right_hand", "left_knee", "right_knee", "left_ankle", "right_ankle")
"""The Kinect joints whose depth agreement measures the lag (the ones that move, and the head)."""

CAP_M = 0.5
"""A joint's disagreement counts at most this much (m): one that lands on another part of the
person far behind or in front of it. A joint that lands on no depth (off the person: the
background is removed) is left out, so each lag is averaged over the joints that land on the
person; that count peaks at the same lag."""


def check_lag(lag_frames: float, where: str) -> float:
    """``lag_frames`` as a float; ConfigError naming ``where`` (a file, a flag) unless it is a
    number of frames within 0 .. :data:`MAX_LAG_FRAMES`."""
    if not (np.isfinite(lag_frames) and 0.0 <= lag_frames <= MAX_LAG_FRAMES):
        raise ConfigError(f"utdmhad: lag={lag_frames:g} for {where} is not a number of frames within "
                          f"0..{MAX_LAG_FRAMES:g} (the frames the depth trails the skeleton); the measured lag is "
                          f"{DEPTH_LAG_FRAMES}, 0 keeps the files' pairing")
    return float(lag_frames)


def synchronised(skeleton: np.ndarray, lag_frames: float) -> np.ndarray:
    """(F, K, 3) the skeleton (F, K, 3) at ``t − lag_frames`` for every frame ``t``: linear
    interpolation between the two nearest frames, held at the first and last frame beyond the
    ends (people stand still there), NaN where a neighbour it uses is NaN."""
    skeleton = np.asarray(skeleton, float)
    count = len(skeleton)
    at = np.clip(np.arange(count) - float(lag_frames), 0.0, count - 1.0)
    below = np.floor(at).astype(int)
    above = np.minimum(below + 1, count - 1)
    weight = at - below
    out = skeleton[below].copy()  # a whole-frame lag needs no neighbour (one untracked must not spread)
    part = weight > 0
    w = weight[part, None, None]
    out[part] = (1.0 - w) * skeleton[below[part]] + w * skeleton[above[part]]
    return out


def depth_agreement_mm(depth: np.ndarray, skeleton: np.ndarray, joints: Sequence[int], intrinsics: Intrinsics,
                       lags: Sequence[float], margin: int = 4) -> np.ndarray:
    """(len(lags),) mean |depth − joint z| mm, each capped at :data:`CAP_M`, of the skeleton's
    ``joints`` (F, K, 3 m, camera frame) at ``t − lag`` projected into depth frame ``t``
    (depth (F, H, W) m, 0 = none), over frames ``margin .. F − margin − 1`` and the pixels
    with depth; NaN for a lag with none."""
    depth = np.asarray(depth)
    frames = np.arange(margin, len(depth) - margin)
    out = []
    for lag in lags:
        points = synchronised(skeleton, lag)[frames][:, list(joints)]  # (T, J, 3)
        frame = np.repeat(frames, points.shape[1])
        points = points.reshape(-1, 3)
        known = np.all(np.isfinite(points), axis=1)
        frame, points = frame[known], points[known]
        uv = np.round(intrinsics.project(points)).astype(int) if len(points) else np.zeros((0, 2), int)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < depth.shape[2]) & (uv[:, 1] >= 0) & (uv[:, 1] < depth.shape[1])
        z = depth[frame[inside], uv[inside, 1], uv[inside, 0]]
        seen = z > 0
        gaps = np.minimum(np.abs(z[seen] - points[inside][seen, 2]), CAP_M)
        out.append(1000.0 * float(gaps.mean()) if len(gaps) else float("nan"))
    return np.array(out)
