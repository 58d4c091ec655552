"""The depth tile: how a TW x TH tile maps onto an image-space box B.

Image pixel ``k`` has its centre at ``k`` (OpenCV, :mod:`swarmpose.core.camera`) and covers
``[k - 0.5, k + 0.5)``. A box ``(u0, v0, bw, bh)`` (pixels, may be fractional) covers the
pixel-index range ``[u0, u0 + bw) x [v0, v0 + bh)``, i.e. the continuous image region
``[u0 - 0.5, u0 + bw - 0.5) x [v0 - 0.5, v0 + bh - 0.5)``. Tile pixel ``(i, j)`` samples the
image point at its centre: ``u_i = u0 - 0.5 + (i + 0.5) bw / TW`` (and likewise ``v_j``), so a
box of TW x TH whole pixels maps tile pixel ``i`` onto image pixel ``u0 + i`` exactly.

Observations are resampled to the tile by nearest neighbour (the image pixel containing
each sample point), which keeps 0 = no measurement meaningful (no averaging across holes
or depth edges). Samples outside the image, and non-finite or non-positive depths, are 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ShapeError


def _check_box(u0: float, v0: float, bw: float, bh: float) -> None:
    vals = (u0, v0, bw, bh)
    if not all(math.isfinite(float(x)) for x in vals) or bw <= 0 or bh <= 0:
        raise ConfigError(f"box (u0, v0, width, height) = {vals} must be finite with positive size")


@dataclass(frozen=True)
class TileBox:
    """An image-space box (u0, v0, bw, bh) in pixels sampled by a tile of tw x th pixels."""

    u0: float
    v0: float
    bw: float
    bh: float
    tw: int
    th: int

    def __post_init__(self) -> None:
        _check_box(self.u0, self.v0, self.bw, self.bh)
        if self.tw < 1 or self.th < 1:
            raise ConfigError(f"tile size {self.tw}x{self.th} must be at least 1x1")

    @property
    def box(self) -> tuple[float, float, float, float]:
        return (self.u0, self.v0, self.bw, self.bh)

    def sample_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Image coordinates (pixels) of the tile pixel centres: u (tw,), v (th,), float64."""
        u = self.u0 - 0.5 + (np.arange(self.tw) + 0.5) * (self.bw / self.tw)
        v = self.v0 - 0.5 + (np.arange(self.th) + 0.5) * (self.bh / self.th)
        return u, v

    def projection(self, intr: Intrinsics) -> tuple[float, float, float, float]:
        """(ax, bx, ay, by) with tile coordinates ``x_t = ax X/Z + bx``, ``y_t = ay Y/Z + by``
        (tile pixel i spans [i, i + 1), centre i + 0.5) for camera points (X, Y, Z) m."""
        sx, sy = self.bw / self.tw, self.bh / self.th
        return (intr.fx / sx, (intr.cx - self.u0 + 0.5) / sx, intr.fy / sy, (intr.cy - self.v0 + 0.5) / sy)

    def rays(self, intr: Intrinsics) -> np.ndarray:
        """Camera rays (th, tw, 6) float32 through the tile pixel centres: origin 0 and
        direction ((u - cx)/fx, (v - cy)/fy, 1), so a hit distance t is the depth z in m."""
        u, v = self.sample_points()
        uu, vv = np.meshgrid(u, v)
        rays = np.zeros((self.th, self.tw, 6), dtype=np.float32)
        rays[..., 3] = (uu - intr.cx) / intr.fx
        rays[..., 4] = (vv - intr.cy) / intr.fy
        rays[..., 5] = 1.0
        return rays

    def resample(self, depth: np.ndarray) -> np.ndarray:
        """Observed depth (H, W) m -> (th, tw) float32 by nearest neighbour; 0 where invalid."""
        depth = np.asarray(depth)
        if depth.ndim != 2:
            raise ShapeError(f"depth has shape {depth.shape}, expected (H, W)")
        h, w = depth.shape
        iu = np.floor(self.u0 + (np.arange(self.tw) + 0.5) * (self.bw / self.tw)).astype(np.int64)
        iv = np.floor(self.v0 + (np.arange(self.th) + 0.5) * (self.bh / self.th)).astype(np.int64)
        ok = ((iv >= 0) & (iv < h))[:, None] & ((iu >= 0) & (iu < w))[None, :]
        out = depth[np.clip(iv, 0, h - 1)[:, None], np.clip(iu, 0, w - 1)[None, :]].astype(np.float32)
        out = np.where(ok & np.isfinite(out) & (out > 0), out, np.float32(0.0))
        return np.ascontiguousarray(out, dtype=np.float32)


def clip_box(box, width: int, height: int) -> tuple[float, float, float, float] | None:
    """The part of box (u0, v0, bw, bh) inside a width x height image (pixel-index ranges
    [0, width) x [0, height)), or None when nothing of it is inside."""
    try:
        u0, v0, bw, bh = (float(x) for x in box)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"box must be (u0, v0, width, height) in pixels, got {box!r}") from exc
    _check_box(u0, v0, bw, bh)
    a, b = max(u0, 0.0), min(u0 + bw, float(width))
    c, d = max(v0, 0.0), min(v0 + bh, float(height))
    if a >= b or c >= d:
        return None
    return (a, c, b - a, d - c)


def box_around(pixels: np.ndarray, margin: float = 0.1) -> tuple[float, float, float, float]:
    """A box (u0, v0, bw, bh) around image points (N, 2) px, grown by ``margin`` of its size
    on every side, with whole-pixel corners."""
    pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        raise ConfigError("box_around needs at least one finite image point")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    grow = margin * (hi - lo) + 1.0
    lo, hi = np.floor(lo - grow), np.ceil(hi + grow)
    return (float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]))
