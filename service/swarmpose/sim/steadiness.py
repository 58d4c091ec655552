"""How still a tracked person stands, and how soon the track follows when they move (issue 53).

On a sequence whose person holds one pose for frames ``[0, n)`` and moves from frame ``n`` on
(a motion spec's ``?hold=``, :mod:`swarmpose.motion.hold`):

* **jitter** of a joint (mm): the standard deviation of its tracked 3D position over the still
  frames, ``sqrt(mean_t |p_t - mean_t p_t|^2)`` (the root of the summed per-axis population
  variances: how far, RMS, the joint sits from where it sits on average). Frames without an
  estimate (NaN) are left out. The truth's jitter there is 0.
* **lag** (ms) when the motion starts: per joint that moves at least :data:`MOVING_M` within the
  first :data:`LAG_WINDOW_S` of the motion, the time shift ``tau`` that best lines its tracked
  displacement up with the truth's there, i.e. that minimises
  ``mean_t |e(t + tau) - e(rest) - (g(t) - g(n - 1))|^2`` with ``e`` the joint's estimates (read
  between frames by linear interpolation), ``e(rest)`` their mean over the still frames and ``g``
  the truth, searched over ``|tau| <=`` :data:`MAX_LAG_S` in 1 ms steps; the lag is the median
  over those joints (a hidden limb that jumps between two fits gives its own lag an outlier's
  value, not the median). A causal filter's lag is > 0; a track that moves before the truth does
  (a centred smoothing reaching into the future) has a lag < 0. Taking each track's still
  position as its rest leaves its constant offset from the truth out.
* **onset Δ**: the mean joint error over the first :data:`ONSET_S` of the motion, beside the
  motion's Δ after it, so a track left behind at the start shows as an onset Δ above the rest.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.errors import ConfigError, check_shape
from swarmpose.sim.evaluate import joint_errors

LAG_WINDOW_S = 0.5
"""The span of motion (s, from its first moving frame) the lag is fitted over."""
MAX_LAG_S = 0.2
"""The largest lag (s, either way) searched."""
LAG_STEP_S = 0.001
MOVING_M = 0.03
"""A joint takes part in the lag when the truth moves it this far (m) within the lag's window."""
ONSET_S = 0.3
"""The motion's first seconds whose Δ is the onset Δ."""


def jitter_mm(estimates: np.ndarray) -> np.ndarray:
    """(J,) per-joint standard deviation (mm) of positions (F, J, 3) m over the frames (module doc);
    NaN for a joint with fewer than 2 known frames."""
    x = np.asarray(estimates, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ConfigError(f"jitter needs joint positions (frames, joints, 3), got shape {x.shape}")
    known = np.all(np.isfinite(x), axis=2)  # (F, J)
    out = np.full(x.shape[1], np.nan)
    for j in range(x.shape[1]):
        p = x[known[:, j], j]
        if len(p) >= 2:
            out[j] = 1000.0 * np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))
    return out


def _shifted(x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """x (F, J, 3) read at fractional frame positions ``at`` (T,) by linear interpolation -> (T, J, 3)."""
    lo = np.clip(np.floor(at).astype(int), 0, len(x) - 2)
    w = (at - lo)[:, None, None]
    return (1.0 - w) * x[lo] + w * x[lo + 1]


def motion_lag_ms(estimates: np.ndarray, truth: np.ndarray, moves_at: int, fps: float, still_from: int = 0,
                  window_s: float = LAG_WINDOW_S, max_lag_s: float = MAX_LAG_S) -> float:
    """The lag (ms) of ``estimates`` behind ``truth`` (F, J, 3) m when the motion starts at frame
    ``moves_at`` (module doc); frames ``[still_from, moves_at)`` are the still ones whose mean is
    the estimates' rest. NaN when an estimate the fit reads is unknown (a lost track has no lag)
    or no joint moves :data:`MOVING_M`; ConfigError when the sequence is too short for the window
    and the search."""
    e, g = np.asarray(estimates, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    check_shape("truth", g, e.shape)
    reach = int(np.ceil(max_lag_s * fps)) + 1
    width = int(round(window_s * fps))
    if not (0 <= still_from < moves_at and moves_at - reach >= 0 and moves_at + width + reach <= len(e)):
        raise ConfigError(f"the lag needs {reach} still frames before the motion starts at frame {moves_at} and "
                          f"{width + reach} frames of motion after it; the sequence has {len(e)}")
    target = g[moves_at:moves_at + width] - g[moves_at - 1]  # (T, J, 3)
    moving = np.linalg.norm(target, axis=2).max(axis=0) >= MOVING_M
    span = e[moves_at - reach:moves_at + width + reach]
    if not moving.any() or not np.all(np.isfinite(span[:, moving])):
        return float("nan")
    rest = np.nanmean(e[still_from:moves_at], axis=0)
    frames = np.arange(moves_at, moves_at + width, dtype=np.float64)
    lags = np.arange(-max_lag_s, max_lag_s + LAG_STEP_S / 2, LAG_STEP_S)
    cost = np.stack([np.mean(np.sum((_shifted(e, frames + tau * fps) - rest - target) ** 2, axis=2), axis=0)
                     for tau in lags])  # (lags, J)
    return round(float(1000.0 * np.median(lags[np.argmin(cost[:, moving], axis=0)])), 3)


def still_report(estimates: np.ndarray, truth: np.ndarray, moves_at: int, fps: float, settle: int = 0,
                 joint_names: tuple[str, ...] | None = None) -> dict:
    """Jitter, still Δ, lag and onset Δ of one track (module doc): estimates and truth (F, J, 3) m,
    the person still for frames < ``moves_at`` and moving from it; the first ``settle`` frames (the
    track's start) are left out of the still ones. Keys: ``jitter_mm`` (mean over joints),
    ``jitter_max_mm`` and ``jitter_worst`` (the joint's name, or index), ``jitter_per_joint_mm``,
    ``still_delta_mm``, ``lag_ms``, ``onset_delta_mm`` and ``moving_delta_mm`` (None where a track
    had no estimate)."""
    e, g = np.asarray(estimates, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    check_shape("truth", g, e.shape)
    if not 0 <= settle < moves_at - 1:
        raise ConfigError(f"the still frames {settle}..{moves_at - 1} hold fewer than 2 frames; hold longer or "
                          "settle less")
    still = e[settle:moves_at]
    jitter = jitter_mm(still)
    names = joint_names or tuple(range(e.shape[1]))
    worst = int(np.nanargmax(jitter)) if np.isfinite(jitter).any() else None
    error = joint_errors(e, g)  # (F, J) mm
    onset_end = moves_at + int(round(ONSET_S * fps))
    lag = motion_lag_ms(e, g, moves_at, fps, settle)

    def mean(values: np.ndarray) -> float | None:
        ok = np.isfinite(values)
        return float(values[ok].mean()) if ok.any() else None

    return {"jitter_mm": mean(jitter), "jitter_max_mm": None if worst is None else float(jitter[worst]),
            "jitter_worst": None if worst is None else names[worst],
            "jitter_per_joint_mm": [None if not np.isfinite(v) else float(v) for v in jitter],
            "still_delta_mm": mean(error[settle:moves_at]),
            "lag_ms": lag if np.isfinite(lag) else None,
            "onset_delta_mm": mean(error[moves_at:onset_end]), "moving_delta_mm": mean(error[onset_end:])}
