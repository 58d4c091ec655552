"""Pinhole intrinsics (OpenCV convention) and camera placement.

Camera frame: x right, y down, z forward, metres. Pixel (u, v) = (fx x/z + cx, fy y/z + cy)
with the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmpose.core.errors import AssetError


@dataclass(frozen=True)
class Intrinsics:
    """width, height: pixels; fx, fy: focal lengths in pixels; cx, cy: principal point."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def kinect_v1(cls) -> Intrinsics:
        """The 640x480 Kinect v1 calibration of the project's real Kinect frame (f = 525)."""
        return cls(640, 480, 525.0, 525.0, 319.5, 239.5)

    @property
    def matrix(self) -> np.ndarray:
        """The (3, 3) camera matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def to_open3d_json(self) -> dict:
        """Open3D's PinholeCameraIntrinsic JSON layout (column-major ``intrinsic_matrix``)."""
        return {"width": self.width, "height": self.height,
                "intrinsic_matrix": [float(x) for x in self.matrix.T.ravel()]}

    @classmethod
    def from_open3d_json(cls, data: dict, source: str = "intrinsics") -> Intrinsics:
        """Parse Open3D's layout; errors name ``source``."""
        try:
            k = np.asarray(data["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T
            return cls(int(data["width"]), int(data["height"]), k[0, 0], k[1, 1], k[0, 2], k[1, 2])
        except (KeyError, ValueError, TypeError) as exc:
            raise AssetError(f"{source}: not an Open3D PinholeCameraIntrinsic JSON "
                             f"(needs width, height, intrinsic_matrix[9]): {exc}") from exc

    def save(self, path: Path) -> None:
        """Write ``intrinsic.json`` in Open3D's layout."""
        Path(path).write_text(json.dumps(self.to_open3d_json(), indent=2))

    @classmethod
    def load(cls, path: Path) -> Intrinsics:
        """Read an Open3D-layout intrinsics file."""
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise AssetError(f"cannot read intrinsics {path}: {exc}") from exc
        return cls.from_open3d_json(data, str(path))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) m -> pixels (..., 2)."""
        return project(points, self.fx, self.fy, self.cx, self.cy)

    def point_map(self, depth: np.ndarray) -> np.ndarray:
        """Back-projected points (H, W, 3) m of a depth image (H, W) m taken with this camera;
        NaN where the depth is 0 or not finite."""
        h, w = depth.shape
        z = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float64)
        u = np.arange(w, dtype=np.float64)[None, :]
        v = np.arange(h, dtype=np.float64)[:, None]
        return np.stack([(u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z], axis=-1)


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """World -> camera rotation (3, 3) (rows = camera x, y, z in world coordinates) of a
    camera at ``eye`` looking at ``target`` with the world's ``up`` appearing upward."""
    z = np.asarray(target, dtype=np.float64) - np.asarray(eye, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def project(points: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """Pinhole projection of camera-frame points (..., 3) m -> pixels (..., 2) (OpenCV)."""
    pts = np.asarray(points, dtype=np.float64)
    z = pts[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([fx * pts[..., 0] / z + cx, fy * pts[..., 1] / z + cy], -1)
