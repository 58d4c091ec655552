"""Dropouts filled for the shape fit: a structured-light sensor loses pixels at depth edges.

A Kinect-like sensor drops many pixels along a depth edge (the simulator: 60 % of the pixels
whose 3 × 3 neighbourhood spans more than 5 cm, on both sides of the edge). The shape fit charges
a model pixel with no observation as if nothing were there (E_S, :mod:`~swarmpose.personalise.personalise`),
so every dropout on the person's outline would pull the fitted body in.

:func:`fill_dropouts` gives a zero pixel the median of its valid 8-neighbours where at least
``min_valid`` of them are valid. A dropout on the person's side of a straight outline has its
three inner neighbours and on average two more (about 0.8 of them the person's, 1.2 the wall's),
so it takes the person's depth; one on the background's side takes the background's. A pixel
just outside a straight or convex stretch of the outline of a person whose background was removed
(UTD-MHAD, a segmented person) has at most three valid neighbours and stays empty. The limit:
there a pixel in a concave corner (an armpit, the crotch) or in a gap one pixel wide between an
arm and the torso has more, and is filled, so the silhouette closes such gaps.
"""

from __future__ import annotations

import warnings

import numpy as np

MIN_VALID = 4
"""The fewest valid 8-neighbours a dropout needs to be filled (see the module docstring)."""
AGREE_M = 0.1
"""A filled pixel's median must have more than half its valid neighbours within this (m) of it:
where they split evenly between the person and the wall, the median is a depth between the
two that neither has, and the pixel stays empty."""


def fill_dropouts(depth: np.ndarray, min_valid: int = MIN_VALID) -> np.ndarray:
    """Depth (H, W) m with 0 = no measurement -> a copy (H, W) float32 in which each zero pixel
    with at least ``min_valid`` valid (> 0) 8-neighbours holds their median, where more than half
    of them lie within :data:`AGREE_M` of it; one pass, so a hole wider than two pixels keeps its
    inside empty."""
    z = np.asarray(depth, dtype=np.float32)
    h, w = z.shape
    padded = np.pad(np.where(z > 0, z, np.nan), 1, constant_values=np.nan)
    neighbours = np.stack([padded[i:i + h, j:j + w] for i in range(3) for j in range(3) if (i, j) != (1, 1)])
    valid = np.isfinite(neighbours).sum(axis=0)
    fill = (z <= 0) & (valid >= min_valid)
    if not fill.any():
        return z.copy()
    around = neighbours[:, fill]  # (8, N), in the order of np.nonzero(fill)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods, never used
        median = np.nanmedian(around, axis=0)
    agree = (np.abs(around - median) <= AGREE_M).sum(axis=0) * 2 > valid[fill]
    out = z.copy()
    rows, cols = np.nonzero(fill)
    out[rows[agree], cols[agree]] = median[agree]
    return out
