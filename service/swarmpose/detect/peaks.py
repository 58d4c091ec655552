"""The prominent peaks of a short 1-D profile (a piece's head-height profile, a few dozen bins).

The same peaks, in the same order, as ``scipy.signal.find_peaks(x, prominence=p, distance=d)``
(which ``tests/detect/test_peaks.py`` holds it to): local maxima (the middle of a flat top), the
lower of two closer than ``distance`` samples removed first, then those whose prominence (height
above the higher of the lowest points either side before a higher sample) is under ``prominence``.
Written out here because importing ``scipy.signal`` costs about a second of every start.
"""

from __future__ import annotations

import numpy as np


def local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the samples higher than their left neighbour and not lower than their right
    one, a flat top counted once at its middle (rounded down); never the first or last sample."""
    peaks = []
    i, last = 1, len(x) - 1
    while i < last:
        if x[i - 1] < x[i]:
            ahead = i + 1
            while ahead < last and x[ahead] == x[i]:
                ahead += 1
            if x[ahead] < x[i]:
                peaks.append((i + ahead - 1) // 2)
                i = ahead
        i += 1
    return np.array(peaks, dtype=np.int64)


def prominences(x: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """Each peak's height above the higher of its two bases (the lowest sample on each side before
    a strictly higher one, or the end)."""
    out = np.empty(len(peaks))
    for k, p in enumerate(peaks):
        left = p
        while left > 0 and x[left - 1] <= x[p]:
            left -= 1
        right = p
        while right < len(x) - 1 and x[right + 1] <= x[p]:
            right += 1
        out[k] = x[p] - max(x[left:p + 1].min(), x[p:right + 1].min())
    return out


def find_peaks(x: np.ndarray, prominence: float, distance: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(peak indices, their prominences) of ``x`` (N,): see the module doc."""
    x = np.asarray(x, dtype=np.float64)
    peaks = local_maxima(x)
    if distance > 1 and len(peaks) > 1:
        keep = np.ones(len(peaks), dtype=bool)
        for k in np.argsort(x[peaks], kind="stable")[::-1]:  # highest first; among equal ones the rightmost
            if keep[k]:
                near = np.abs(peaks - peaks[k]) < distance
                near[k] = False
                keep[near] = False
        peaks = peaks[keep]
    values = prominences(x, peaks)
    chosen = values >= prominence
    return peaks[chosen], values[chosen]
