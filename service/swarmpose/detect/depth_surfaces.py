"""The measuring half of :mod:`swarmpose.detect.people`: its tuning, and one depth frame's
candidate surfaces measured along the floor (height, across and along the view, frontal area),
judged person or not (step 5 of that module's docstring).

Camera frame: OpenCV axes, x right, y down, z forward, metres; pixels px.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, fields

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.detect.floor import FloorPlane


@dataclass(frozen=True)
class PeopleTuning:
    """Knobs of :func:`segment_people`; lengths in metres, areas in m^2, pixels in px."""

    min_depth_m: float = 0.4
    max_depth_m: float = 8.5
    floor_clearance_m: float = 0.06
    step_base_m: float = 0.05
    step_per_m2: float = 0.02
    stride: int = 2
    min_area_m2: float = 0.12
    noise_area_m2: float = 0.003
    min_width_m: float = 0.2
    max_width_m: float = 1.3
    min_vertical_m: float = 0.4
    max_vertical_m: float = 2.4
    min_top_m: float = 0.9
    max_top_m: float = 2.3
    head_dip_m: float = 0.12
    min_head_separation_m: float = 0.3
    profile_bin_m: float = 0.03
    min_part_share: float = 0.3
    attach_distance_m: float = 0.4
    attach_gap_m: float = 0.1
    min_relief_m: float = 0.02
    min_occluded_share: float = 0.4
    fill_m: float = 0.03
    max_fill_px: int = 8

    @classmethod
    def from_kwargs(cls, tuning: dict) -> PeopleTuning:
        """Build from keyword overrides; an unknown name raises ConfigError listing the known ones."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(tuning) - known)
        if unknown:
            raise ConfigError(f"segment_people: unknown tuning option(s) {unknown}; known: {sorted(known)}")
        out = cls(**tuning)
        if out.stride < 1 or out.max_fill_px < 0 or not 0 < out.min_depth_m < out.max_depth_m:
            raise ConfigError(f"segment_people: need stride >= 1, max_fill_px >= 0 and "
                              f"0 < min_depth_m < max_depth_m, got {out}")
        return out


SUPPORT_POINTS = 3
SUPPORT_M = 0.03
"""The head top (and lowest point) is the highest (lowest) point with ``SUPPORT_POINTS`` more
points within ``SUPPORT_M`` below (above) it: robust to a few stray pixels, unbiased by size."""


@functools.lru_cache(maxsize=4)
def axis_factors(intrinsics: Intrinsics, up: tuple[float, float, float]) -> tuple[np.ndarray, ...]:
    """Per-pixel factors (H, W) float32 turning depth z into the height, across and along
    coordinates (m) of a pixel's point: coordinate = z * factor (+ the floor's offset for
    height). ``up``: the floor's upward normal or the camera's -y; across: horizontal and
    across the view; along: horizontal and along it."""
    up_v = np.asarray(up, dtype=np.float64)
    across = np.array([1.0, 0.0, 0.0]) - up_v[0] * up_v
    across /= np.linalg.norm(across)
    along = np.cross(across, up_v)
    x = ((np.arange(intrinsics.width) - intrinsics.cx) / intrinsics.fx)[None, :]
    y = ((np.arange(intrinsics.height) - intrinsics.cy) / intrinsics.fy)[:, None]
    out = tuple((a[0] * x + a[1] * y + a[2]).astype(np.float32) for a in (up_v, across, along))
    for f in out:
        f.flags.writeable = False
    return out


@dataclass
class Coords:
    """Points of a piece (N,): height, across, along (m), pixel footprint area (m^2), pixel u, v."""

    h: np.ndarray
    across: np.ndarray
    along: np.ndarray
    area: np.ndarray
    u: np.ndarray
    v: np.ndarray


@dataclass
class Piece:
    """A candidate surface: its full-resolution mask inside box (x0, y0, x1, y1) px."""

    box: tuple[int, int, int, int]
    mask: np.ndarray
    stats: dict = field(default_factory=dict)
    reason: str | None = None
    cache: dict = field(default_factory=dict)


class SurfaceFrame:
    """One depth frame with the per-pixel coordinate maps the segmentation measures with."""

    def __init__(self, depth: np.ndarray, intrinsics: Intrinsics, floor: FloorPlane | None, cfg: PeopleTuning):
        self.depth, self.intrinsics, self.floor, self.cfg = depth, intrinsics, floor, cfg
        up = (0.0, -1.0, 0.0) if floor is None else tuple(float(v) for v in floor.normal)
        self.height, self.across, self.along = axis_factors(intrinsics, up)
        self.height_offset = 0.0 if floor is None else float(floor.offset)
        self.footprint = np.float32(1.0 / (intrinsics.fx * intrinsics.fy))

    def step(self, z: np.ndarray) -> np.ndarray:
        """The largest depth difference (m) between neighbours of one surface at depth z (m)."""
        return self.cfg.step_base_m + self.cfg.step_per_m2 * z * z

    def coords(self, piece: Piece, stride: int) -> Coords:
        """The points of every ``stride``-th pixel of the piece that has depth (memoised)."""
        if stride not in piece.cache:
            x0, y0, x1, y1 = piece.box
            win = np.s_[y0:y1:stride, x0:x1:stride]
            z = self.depth[win]
            keep = piece.mask[::stride, ::stride] & (z > 0)
            zs = z[keep]
            v, u = np.nonzero(keep)
            piece.cache[stride] = Coords(zs * self.height[win][keep] + self.height_offset,
                                          zs * self.across[win][keep], zs * self.along[win][keep],
                                          zs * zs * (self.footprint * stride * stride),
                                          u * stride + x0, v * stride + y0)
        return piece.cache[stride]

    def measure(self, piece: Piece) -> dict:
        """The piece's size on every ``cfg.stride``-th pixel (see PersonSegment): area_m2 and
        points, and with 8 points or more top, bottom, vertical, width (m), centroid (3,) m."""
        p = self.coords(piece, self.cfg.stride)
        s = {"area_m2": float(p.area.sum()), "points": len(p.h)}
        if len(p.h) >= 8:
            top, bottom = supported_top(p.h), -supported_top(-p.h)
            left, right = np.percentile(p.across, [2.0, 98.0])
            z = self.depth[p.v, p.u]
            intr = self.intrinsics
            xyz = np.stack([(p.u - intr.cx) / intr.fx * z, (p.v - intr.cy) / intr.fy * z, z])
            s.update(top=top, bottom=bottom, vertical=top - bottom, width=float(right - left),
                     centroid=np.median(xyz, axis=1))
        return s

    def judge(self, piece: Piece) -> Piece:
        """Measure the piece and set ``reason``: None for a person, else why not (step 5 of
        the module docstring); returns the piece."""
        c = self.cfg
        if piece.stats.get("area_m2", np.inf) < c.min_area_m2:  # known from the labelling
            piece.reason = "too_small"
            return piece
        s = piece.stats = self.measure(piece)
        if s["area_m2"] < c.min_area_m2 or s["points"] < 8:
            piece.reason = "too_small"
            return piece
        p, top = self.coords(piece, c.stride), s["top"]
        with_floor = self.floor is not None
        for reason, failed in (("too_wide", s["width"] > c.max_width_m), ("too_tall", s["vertical"] > c.max_vertical_m),
                               ("too_narrow", s["width"] < c.min_width_m),
                               ("too_short", s["vertical"] < c.min_vertical_m),
                               ("too_low", with_floor and top < c.min_top_m),
                               ("too_high", with_floor and top > c.max_top_m)):
            if failed:
                piece.reason = reason
                return piece
        points = np.stack([p.h, p.across, p.along], -1)
        flatness = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(points))
        piece.reason = "flat" if flatness < c.min_relief_m else None
        return piece

    def occluded_share(self, piece: Piece) -> float:
        """Share of the piece's outline pixels that have a nearer surface (by more than a
        depth step) within 3 px: near 1 for background seen only through a gap in a nearer
        surface (the wall between a person's arm and body)."""
        import cv2

        if "nearest7" not in self.__dict__:
            valid = np.where(self.depth > 0, self.depth, np.float32(np.inf))
            self.nearest7 = cv2.erode(valid, np.ones((7, 7), np.uint8), borderType=cv2.BORDER_REPLICATE)
        x0, y0, x1, y1 = piece.box
        inner = cv2.erode(piece.mask.view(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                          borderValue=0).view(bool)
        outline = piece.mask & ~inner
        z = self.depth[y0:y1, x0:x1][outline]
        nearer = self.nearest7[y0:y1, x0:x1][outline] < z - self.step(z)
        return float(nearer.mean()) if z.size else 0.0


def supported_top(h: np.ndarray) -> float:
    """The highest value of h (N,) with SUPPORT_POINTS more values within SUPPORT_M below it."""
    k = SUPPORT_POINTS
    if len(h) <= k:
        return float(h.min())
    top = np.sort(np.partition(h, len(h) - min(len(h), 64))[-64:])[::-1]
    ok = np.flatnonzero(top[:len(top) - k] - top[k:] <= SUPPORT_M)
    return float(top[ok[0]] if ok.size else top[len(top) // 2])
