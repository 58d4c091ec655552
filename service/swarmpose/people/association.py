"""Frame-to-frame association of tracks and the people seen in a frame.

The cost of pairing track t with observation o is the distance (m) between where the track
is expected (its last centre moved by its velocity) and the observation's centre, plus an
appearance term: the Bhattacharyya distance (0 = same, 1 = disjoint) between the colour
histograms of the two, times ``appearance_m`` metres. Pairs costing more than ``gate_m`` are
never made. The assignment minimising the total cost is scipy's
:func:`~scipy.optimize.linear_sum_assignment` (Hungarian method).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HUE_BINS, SATURATION_BINS = 12, 4
"""Colour histogram size: hue × saturation (brightness is left out: it changes with light)."""

NO_PAIR = 1e9
"""The cost that stands for a pair outside the gate (finite: the solver needs finite costs)."""


@dataclass(frozen=True)
class Assignment:
    """pairs: (track index, observation index) matched; lone_tracks / lone_observations: the rest."""

    pairs: tuple[tuple[int, int], ...]
    lone_tracks: tuple[int, ...]
    lone_observations: tuple[int, ...]


def colour_histogram(color: np.ndarray | None, mask: np.ndarray) -> np.ndarray | None:
    """Normalised hue × saturation histogram (HUE_BINS * SATURATION_BINS,) of the pixels of
    ``color`` (H, W, 3) uint8 RGB under ``mask`` (H, W) bool; None without colour or pixels.
    Nearly grey pixels (saturation < 10 %) fall in the lowest saturation bins of their hue."""
    import cv2

    if color is None or not np.any(mask):
        return None
    pixels = np.ascontiguousarray(color[mask][None, :, :3], dtype=np.uint8)
    hsv = cv2.cvtColor(pixels, cv2.COLOR_RGB2HSV)[0]
    hue = (hsv[:, 0].astype(np.int64) * HUE_BINS) // 180
    sat = (hsv[:, 1].astype(np.int64) * SATURATION_BINS) // 256
    hist = np.bincount(hue * SATURATION_BINS + sat, minlength=HUE_BINS * SATURATION_BINS).astype(np.float64)
    return hist / hist.sum()


def bhattacharyya(a: np.ndarray | None, b: np.ndarray | None) -> float:
    """Bhattacharyya distance sqrt(1 − Σ sqrt(a·b)) of two normalised histograms, 0..1; 0 when
    either is unknown (appearance then does not count)."""
    if a is None or b is None:
        return 0.0
    return float(np.sqrt(max(0.0, 1.0 - float(np.sum(np.sqrt(a * b))))))


def pair_costs(expected: np.ndarray, observed: np.ndarray, track_looks: list[np.ndarray | None],
               observed_looks: list[np.ndarray | None], appearance_m: float,
               gate_m: float | np.ndarray) -> np.ndarray:
    """Cost matrix (T, O): distance (m) between ``expected`` (T, 3) and ``observed`` (O, 3)
    centres plus ``appearance_m`` × the looks' Bhattacharyya distance; :data:`NO_PAIR` beyond
    ``gate_m`` (one for all, or (T,) one per track) or where a centre is not finite."""
    expected = np.asarray(expected, dtype=np.float64).reshape(-1, 3)
    observed = np.asarray(observed, dtype=np.float64).reshape(-1, 3)
    cost = np.linalg.norm(expected[:, None, :] - observed[None, :, :], axis=2)
    for t, look in enumerate(track_looks):
        for o, other in enumerate(observed_looks):
            cost[t, o] += appearance_m * bhattacharyya(look, other)
    cost[~np.isfinite(cost) | (cost > np.reshape(gate_m, (-1, 1)))] = NO_PAIR
    return cost


def assign(cost: np.ndarray) -> Assignment:
    """The cheapest one-to-one pairing of rows (tracks) and columns (observations) of ``cost``
    (T, O); pairs at :data:`NO_PAIR` are left unpaired. One track or one observation pairs
    with its cheapest partner directly: scipy's solver (whose import costs a start 0.2-0.3 s)
    only decides between several of each."""
    cost = np.asarray(cost, dtype=np.float64)
    n_tracks, n_obs = cost.shape
    pairs: list[tuple[int, int]] = []
    if n_tracks == 1 and n_obs:
        rows, cols = np.zeros(1, dtype=int), np.argmin(cost, axis=1)
    elif n_obs == 1 and n_tracks:
        rows, cols = np.argmin(cost, axis=0), np.zeros(1, dtype=int)
    elif n_tracks and n_obs:
        from scipy.optimize import linear_sum_assignment

        rows, cols = linear_sum_assignment(cost)
    if n_tracks and n_obs:
        pairs = [(int(r), int(c)) for r, c in zip(rows, cols) if cost[r, c] < NO_PAIR]
    used_t, used_o = {p[0] for p in pairs}, {p[1] for p in pairs}
    return Assignment(tuple(pairs), tuple(t for t in range(n_tracks) if t not in used_t),
                      tuple(o for o in range(n_obs) if o not in used_o))
