"""A Kinect-like depth noise model for synthetic sequences.

Applied to a clean depth image (H, W) in metres (0 = no measurement), in this order:

1. **Axial noise**: Gaussian with ``sigma(z) = axial_a + axial_b (z - axial_z0)^2`` metres
   (Nguyen, Izadi & Lovell 2012 for Kinect v1: 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2).
2. **Disparity quantisation**: a structured-light camera measures disparity
   ``d = f b / z`` in steps of ``1 / subpixel`` pixel, so depth comes in steps of about
   ``z^2 / (f b subpixel)`` (f = 580 px, b = 7.5 cm, 1/8 px: 2.9 mm at 1 m, 2.6 cm at 3 m).
3. **Edge dropout**: a pixel whose 3x3 neighbourhood spans more than ``edge_jump`` metres
   of depth is lost with probability ``edge_dropout``.
4. **Random dropout**: any pixel is lost with probability ``random_dropout``.
5. **Range**: readings outside ``[min_range, max_range]`` become 0.

Seeded: the same image, parameters and seed give the same output.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class KinectNoise:
    """Parameters of the noise model (metres, pixels, probabilities); see the module doc."""

    axial_a: float = 0.0012
    axial_b: float = 0.0019
    axial_z0: float = 0.4
    focal_px: float = 580.0
    baseline_m: float = 0.075
    subpixel: int = 8
    quantise: bool = True
    edge_jump: float = 0.05
    edge_dropout: float = 0.6
    random_dropout: float = 0.005
    min_range: float = 0.4
    max_range: float = 8.0

    def sigma(self, z: np.ndarray) -> np.ndarray:
        """Axial noise standard deviation (m) at depth ``z`` (m)."""
        return self.axial_a + self.axial_b * (np.asarray(z) - self.axial_z0) ** 2

    def step(self, z: np.ndarray) -> np.ndarray:
        """Quantisation step (m) at depth ``z`` (m), to first order."""
        return np.asarray(z) ** 2 / (self.focal_px * self.baseline_m * self.subpixel)

    def as_dict(self) -> dict:
        """The parameters, for writing next to a sequence."""
        return asdict(self)

    def apply(self, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy copy (H, W) float32 m of a clean depth image (H, W) m, 0 = invalid."""
        z = np.asarray(depth, dtype=np.float64)
        valid = z > 0
        out = z + rng.standard_normal(z.shape) * self.sigma(z)
        if self.quantise:
            fb = self.focal_px * self.baseline_m * self.subpixel
            disparity = np.round(fb / np.where(valid, np.maximum(out, 1e-3), 1.0))
            out = fb / np.maximum(disparity, 1.0)
        edges = _depth_edges(z, self.edge_jump)
        lost = (edges & (rng.random(z.shape) < self.edge_dropout)) | (rng.random(z.shape) < self.random_dropout)
        keep = valid & ~lost & (out >= self.min_range) & (out <= self.max_range)
        return np.where(keep, out, 0.0).astype(np.float32)


def _depth_edges(z: np.ndarray, jump: float) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood (invalid pixels excluded) spans more than ``jump`` m,
    or that border an invalid pixel."""
    big = np.where(z > 0, z, np.nan)
    pad = np.pad(big, 1, mode="edge")
    h, w = z.shape
    stack = np.stack([pad[i:i + h, j:j + w] for i in range(3) for j in range(3)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods of holes
        span = np.nanmax(stack, axis=0) - np.nanmin(stack, axis=0)
    touches_hole = np.any(np.isnan(stack), axis=0)
    return (z > 0) & ((np.nan_to_num(span) > jump) | touches_hole)

