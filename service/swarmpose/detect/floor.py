"""The floor plane of one depth frame, found by RANSAC.

Method: the depth image is back-projected on a regular pixel grid (every ``stride``-th pixel
in both directions) into camera-frame points (OpenCV axes: x right, y down, z forward,
metres). Each grid point gets a normal from the cross product of its neighbours' differences;
only points whose normal lies within ``max_tilt_deg + normal_slack_deg`` of the camera's up
axis (-y) go into Open3D's RANSAC (``PointCloud.segment_plane``), so people's backs and walls,
which often hold more points than the floor, cannot win. The plane with the most inliers is
accepted as the floor only if

* it is roughly horizontal: its upward normal is within ``max_tilt_deg`` of the camera's
  -y axis (a camera pitched down by up to ~45 degrees, rolled a little, still qualifies);
* it has enough inliers among all sampled points (``min_inlier_share`` and ``min_inliers``);
* it lies below the scene: the camera is at least ``min_camera_height_m`` above it, and at
  most ``max_below_share`` of the sampled points lie more than ``below_margin_m`` under it.

Otherwise the plane's inliers are removed and the next plane is tried (``attempts`` in all),
so that a table top or a stair found first is not taken for the floor. RANSAC sees at most
``max_ransac_points`` of the candidates (a seeded random choice); the accepted plane is
refitted by least squares (SVD) to all candidates within ``distance_threshold_m`` of it, which
is more accurate than the three-point RANSAC hypothesis. Open3D's global random generator is
seeded with ``seed`` on every call, so the result is repeatable. About 3-10 ms for a 640x480
frame on one core (stride 4).

Limits: a floor covering only a sliver of the image (fewer than ``min_inlier_share`` of the
points) is not found; a large horizontal surface that lies under everything else (a table
filmed from above with no floor in view) is taken for the floor; stairs or a ramp give the
dominant step or an averaged plane.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ShapeError
from swarmpose.core.open3d_import import open3d

UP_IN_CAMERA = np.array([0.0, -1.0, 0.0])
"""The camera's up direction (OpenCV axes: y points down)."""


@dataclass(frozen=True)
class FloorTuning:
    """Knobs of :func:`fit_floor`; lengths in metres, angles in degrees."""

    stride: int = 4
    distance_threshold_m: float = 0.04
    ransac_iterations: int = 100
    max_ransac_points: int = 1500
    attempts: int = 4
    max_tilt_deg: float = 55.0
    normal_slack_deg: float = 15.0
    min_inliers: int = 300
    min_inlier_share: float = 0.04
    min_camera_height_m: float = 0.2
    below_margin_m: float = 0.15
    max_below_share: float = 0.03
    max_depth_m: float = 10.0
    seed: int = 0

    @classmethod
    def from_kwargs(cls, tuning: dict, caller: str = "fit_floor") -> FloorTuning:
        """Build from keyword overrides; an unknown name raises ConfigError listing the known ones."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(tuning) - known)
        if unknown:
            raise ConfigError(f"{caller}: unknown tuning option(s) {unknown}; known: {sorted(known)}")
        out = cls(**tuning)
        if out.stride < 1 or out.attempts < 1 or out.ransac_iterations < 1:
            raise ConfigError(f"{caller}: stride, attempts and ransac_iterations must be >= 1, got {out}")
        return out


@dataclass(frozen=True)
class FloorPlane:
    """The floor as a plane in the camera frame.

    normal: (3,) unit vector pointing from the floor up into the room; offset: metres, so that
    ``normal @ x + offset = 0`` on the floor and ``offset`` is the camera's height above it;
    inliers: RANSAC inliers among the sampled points; tilt_deg: angle between ``normal`` and
    the camera's up axis (-y), degrees.
    """

    normal: np.ndarray
    offset: float
    inliers: int
    tilt_deg: float = 0.0

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed height (...,) m above the floor of camera-frame points (..., 3) m."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.shape[-1:] != (3,):
            raise ShapeError(f"points has shape {pts.shape}, expected (N, 3)")
        return pts @ self.normal + self.offset

    @property
    def camera_height_m(self) -> float:
        """Height of the camera's optical centre above the floor, metres."""
        return float(self.offset)

    def as_dict(self) -> dict:
        """JSON-friendly: normal (list of 3), offset_m, inliers, tilt_deg."""
        return {"normal": [round(float(v), 6) for v in self.normal], "offset_m": round(float(self.offset), 6),
                "inliers": int(self.inliers), "tilt_deg": round(float(self.tilt_deg), 3)}


def check_depth(depth_m: np.ndarray, intrinsics: Intrinsics, name: str = "depth_m") -> np.ndarray:
    """The depth (H, W) as float32 metres with 0 wherever it is 0, negative or not finite.

    Raises ShapeError unless ``depth_m`` is 2-D and (intrinsics.height, intrinsics.width).
    """
    depth = np.asarray(depth_m)
    expected = (intrinsics.height, intrinsics.width)
    if depth.ndim != 2 or depth.shape != expected:
        raise ShapeError(f"{name} has shape {depth.shape}, expected {expected} (height, width) of the "
                         "intrinsics; pass one depth image in metres registered to that camera")
    if np.issubdtype(depth.dtype, np.integer):
        raise ShapeError(f"{name} has dtype {depth.dtype}, expected float metres "
                         "(for a sensor's millimetres, divide millimetres by 1000)")
    if not np.issubdtype(depth.dtype, np.floating):
        raise ShapeError(f"{name} has dtype {depth.dtype}, expected float metres")
    out = depth.astype(np.float32, copy=True)
    out[~(np.isfinite(out) & (out > 0))] = 0.0
    return out


def sample_grid(depth: np.ndarray, intrinsics: Intrinsics, stride: int, max_depth_m: float) -> np.ndarray:
    """Camera-frame points (H // stride, W // stride, 3) m of every ``stride``-th pixel; NaN
    where the depth is missing or beyond ``max_depth_m``."""
    z = depth[::stride, ::stride].astype(np.float64)
    z[~((z > 0) & (z < max_depth_m))] = np.nan
    u = np.arange(0, depth.shape[1], stride, dtype=np.float64)[None, :]
    v = np.arange(0, depth.shape[0], stride, dtype=np.float64)[:, None]
    return np.stack([(u - intrinsics.cx) / intrinsics.fx * z, (v - intrinsics.cy) / intrinsics.fy * z, z], -1)


def grid_normals(grid: np.ndarray) -> np.ndarray:
    """Unit normals (h, w, 3) of an organised point grid (h, w, 3) by central differences
    (sign arbitrary); NaN on the border and next to missing points."""
    normals = np.full_like(grid, np.nan)
    across = grid[1:-1, 2:] - grid[1:-1, :-2]
    down = grid[2:, 1:-1] - grid[:-2, 1:-1]
    cross = np.cross(across, down)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals[1:-1, 1:-1] = cross / np.linalg.norm(cross, axis=-1, keepdims=True)
    return normals


def plane_fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane (unit normal (3,), offset: ``normal @ p + offset = 0`` on it) through
    points (N, 3), by SVD about their mean."""
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre, full_matrices=False)[2][-1]
    return normal, float(-normal @ centre)


def ransac_plane_inliers(points: np.ndarray, within: float, hypotheses: int, seed: int = 0) -> np.ndarray:
    """The points (M, 3) of ``points`` (N, 3) m within ``within`` (m) of the plane through three of
    them that has the most such points, out of ``hypotheses`` random triples drawn by a generator
    of its own seeded with ``seed``. Not Open3D's ``segment_plane``, which :func:`fit_floor` uses: that
    draws from one process-wide generator, so a caller in another thread than the detection thread's
    floor fit (the automatic height's measure, :mod:`swarmpose.personalise.stature`) would make neither
    repeat."""
    if len(points) < 3:
        return points[:0]
    triples = points[np.random.default_rng(seed).integers(0, len(points), (hypotheses, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    good = length > 1e-12
    if not np.any(good):
        return points[:0]
    normals, anchors = normals[good] / length[good, None], triples[good, 0]
    near = np.abs((points[None] - anchors[:, None]) @ normals[..., None])[..., 0] < within  # (K, N)
    return points[near[int(np.argmax(near.sum(axis=1)))]]


def _upward(normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    """The same plane with its normal turned towards the camera's up side."""
    return (normal, offset) if normal @ UP_IN_CAMERA >= 0 else (-normal, -offset)


def fit_floor(depth_m: np.ndarray, intrinsics: Intrinsics, **tuning) -> FloorPlane | None:
    """The floor plane of a depth image (H, W) m (0 or NaN = no measurement), or None where
    no plane passes the floor tests (see the module docstring; ``tuning`` overrides the
    fields of :class:`FloorTuning`)."""
    o3d = open3d()

    cfg = FloorTuning.from_kwargs(tuning)
    depth = check_depth(depth_m, intrinsics)
    grid = sample_grid(depth, intrinsics, cfg.stride, cfg.max_depth_m)
    valid = np.isfinite(grid[..., 2])
    points = grid[valid]
    total = len(points)
    needed = max(cfg.min_inliers, int(np.ceil(cfg.min_inlier_share * total)))
    with np.errstate(invalid="ignore"):
        upness = np.abs(grid_normals(grid)[valid] @ UP_IN_CAMERA)
    candidates = np.flatnonzero(upness >= np.cos(np.radians(min(cfg.max_tilt_deg + cfg.normal_slack_deg, 90.0))))
    cos_tilt = np.cos(np.radians(cfg.max_tilt_deg))
    o3d.utility.random.seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    for _ in range(cfg.attempts):
        if len(candidates) < max(needed, 3):
            return None
        sample = candidates if len(candidates) <= cfg.max_ransac_points else \
            rng.choice(candidates, cfg.max_ransac_points, replace=False)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[sample]))
        model, _ = cloud.segment_plane(cfg.distance_threshold_m, 3, cfg.ransac_iterations)
        model = np.asarray(model, dtype=np.float64)
        near = np.abs(points[candidates] @ model[:3] + model[3]) <= cfg.distance_threshold_m * np.linalg.norm(model[:3])
        picked = candidates[near]
        if len(picked) < 3:
            return None
        normal, offset = _upward(*plane_fit(points[picked]))
        heights = points @ normal + offset
        on_plane = np.abs(heights) <= cfg.distance_threshold_m
        inliers = int(np.count_nonzero(on_plane))
        horizontal = normal @ UP_IN_CAMERA >= cos_tilt
        below = np.count_nonzero(heights < -cfg.below_margin_m) / total
        if (horizontal and inliers >= needed and offset >= cfg.min_camera_height_m
                and below <= cfg.max_below_share):
            tilt = float(np.degrees(np.arccos(np.clip(normal @ UP_IN_CAMERA, -1.0, 1.0))))
            return FloorPlane(normal=normal, offset=offset, inliers=inliers, tilt_deg=tilt)
        candidates = candidates[~on_plane[candidates]]
        candidates = np.setdiff1d(candidates, picked, assume_unique=True)
    return None


__all__ = ["FloorPlane", "FloorTuning", "check_depth", "fit_floor", "grid_normals", "plane_fit", "sample_grid"]
