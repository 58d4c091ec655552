"""Flips of a track against its ground truth: frames whose torso faces the wrong way or whose
left and right sides are swapped, and how long the track takes to come right again.

Per frame, with estimates and truth (F, J, 3) m in ``EVAL_JOINTS`` order (NaN rows where the
body was lost):

* *flipped*: the estimated torso's facing (:func:`swarmpose.sim.evaluate.torso_facing`) lies
  more than :data:`FLIP_DEG` from the truth's;
* *sides swapped*: the estimate's left/right joints of :data:`SIDE_PAIRS` fit the truth better
  with their labels exchanged (summed distances);
* *wrong*: flipped or sides swapped; *right*: an estimate that is neither; a lost frame is
  neither right nor wrong.

A *flip* is a run of frames from a wrong frame (after a right or lost one, or the first) up to
the next right frame; its recovery time is the time from its first frame to that right frame.
A flip still on at the last frame has no right frame: it counts to the end of the sequence (the
last frame's time plus one frame period) and the cell's ``unrecovered`` says so.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.errors import check_shape
from swarmpose.sim.evaluate import facing_errors_deg

FLIP_DEG = 90.0
"""A torso facing more than this (degrees) from the truth's is flipped."""
SIDE_PAIRS = (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"))
"""The left/right joint pairs whose labels are judged (the torso's)."""


def flipped_frames(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F,) bool: the estimated torso faces more than :data:`FLIP_DEG` from the truth's (False
    where either is unknown)."""
    errors = facing_errors_deg(estimates, truth)
    return np.nan_to_num(errors, nan=0.0) > FLIP_DEG


def sides_swapped(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F,) bool: the estimate's :data:`SIDE_PAIRS` lie closer to the truth with left and right
    exchanged (False where a joint of the pairs is unknown)."""
    estimates, truth = np.asarray(estimates, float), np.asarray(truth, float)
    check_shape("estimated joints", estimates, truth.shape)
    index = {name: k for k, name in enumerate(EVAL_JOINTS)}
    kept = np.zeros(len(truth))
    crossed = np.zeros(len(truth))
    for left, right in SIDE_PAIRS:
        el, er, tl, tr = (a[:, index[n]] for a in (estimates, truth) for n in (left, right))
        kept += np.linalg.norm(el - tl, axis=1) + np.linalg.norm(er - tr, axis=1)
        crossed += np.linalg.norm(el - tr, axis=1) + np.linalg.norm(er - tl, axis=1)
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(crossed, nan=np.inf) < np.nan_to_num(kept, nan=-np.inf)


def flips(wrong: np.ndarray, found: np.ndarray) -> list[tuple[int, int | None]]:
    """(first frame, first right frame after it or None) of every flip of a track whose frames
    are ``wrong`` (F,) bool and have an estimate where ``found`` (F,) bool (see the module doc)."""
    wrong, found = np.asarray(wrong, bool), np.asarray(found, bool)
    check_shape("found frames", found, wrong.shape)
    right = found & ~wrong
    out: list[tuple[int, int | None]] = []
    start = None
    for k in range(len(wrong)):
        if start is None and wrong[k] and found[k]:
            start = k
        elif start is not None and right[k]:
            out.append((start, k))
            start = None
    if start is not None:
        out.append((start, None))
    return out


def flip_metrics(estimates: np.ndarray, truth: np.ndarray, times_s: np.ndarray) -> dict:
    """A track's flips against its truth (F, J, 3) m, frames captured at ``times_s`` (F,) s:
    ``flipped`` and ``sides_swapped`` frames, ``flips`` (how many), ``recovery_mean_s`` and
    ``recovery_max_s`` over them (None without a flip) and ``unrecovered`` (1 when the last flip
    lasted to the end and was counted to it, else 0)."""
    estimates, truth, times_s = (np.asarray(a, float) for a in (estimates, truth, times_s))
    check_shape("estimated joints", estimates, truth.shape)
    check_shape("frame times", times_s, (len(truth),))
    flipped = flipped_frames(estimates, truth)
    swapped = sides_swapped(estimates, truth)
    found = np.isfinite(estimates).all(axis=(1, 2))
    episodes = flips(flipped | swapped, found)
    period = float(np.median(np.diff(times_s))) if len(times_s) > 1 else 0.0
    end = float(times_s[-1]) + period if len(times_s) else 0.0
    recovery = [(float(times_s[stop]) if stop is not None else end) - float(times_s[first])
                for first, stop in episodes]
    return {"flipped": int(flipped.sum()), "sides_swapped": int(swapped.sum()), "flips": len(episodes),
            "recovery_mean_s": float(np.mean(recovery)) if recovery else None,
            "recovery_max_s": float(np.max(recovery)) if recovery else None,
            "unrecovered": int(bool(episodes) and episodes[-1][1] is None)}
