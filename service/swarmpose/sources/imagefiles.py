"""Reading depth and colour images and intrinsics files into swarmpose's conventions.

Depth files are single-channel uint16 PNGs in a fixed unit (millimetres: 1000 per metre;
TUM RGB-D: 5000 per metre) and come out as float32 metres with 0 = no measurement.
Colour files (PNG, JPEG) come out as uint8 RGB (H, W, 3). Every failure raises
:class:`~swarmpose.core.errors.SourceError` naming the file, so folder readers can turn it into a
:class:`~swarmpose.sources.base.SkippedFrame`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import AssetError, SourceError

MILLIMETRES = 1000.0
"""Depth units per metre of Open3D's and swarmpose's own PNGs."""


def depth_to_metres(raw: np.ndarray, units_per_metre: float) -> np.ndarray:
    """(H, W) integer depth in sensor units -> (H, W) float32 metres; 0 stays 0 (no measurement)."""
    return (np.asarray(raw, dtype=np.float32) / np.float32(units_per_metre)).astype(np.float32)


def _imread(path: Path, what: str) -> np.ndarray:
    """The pixels of an image file as stored (OpenCV order); SourceError naming ``what`` and the
    path when the file is missing or cannot be decoded."""
    import cv2

    if not path.is_file():
        raise SourceError(f"{what} {path} is missing")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SourceError(f"{what} {path} cannot be decoded (corrupt or not an image)")
    return img


def read_depth(path: Path, units_per_metre: float = MILLIMETRES) -> np.ndarray:
    """A uint16 depth PNG -> (H, W) float32 metres. SourceError for a missing, corrupt or non-16-bit file."""
    path = Path(path)
    raw = _imread(path, "depth image")
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise SourceError(f"depth image {path} is {raw.dtype} with shape {raw.shape}; "
                          "expected single-channel uint16 (depth units)")
    return depth_to_metres(raw, units_per_metre)


def read_color(path: Path) -> np.ndarray:
    """A colour image (PNG/JPEG; grey, BGR or BGRA on disk) -> (H, W, 3) uint8 RGB."""
    import cv2

    path = Path(path)
    img = _imread(path, "colour image")
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8:
        raise SourceError(f"colour image {path} has pixel type {img.dtype}; expected 8-bit")
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    if img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    raise SourceError(f"colour image {path} has {img.shape[2]} channels; expected 1, 3 or 4")


def image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) of an image file without keeping the pixels; None if it cannot be decoded."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return None if img is None else (int(img.shape[1]), int(img.shape[0]))


def load_intrinsics(path: Path) -> tuple[Intrinsics, float | None]:
    """Read a pinhole intrinsics JSON: Open3D's PinholeCameraIntrinsic layout (``width``, ``height``,
    column-major ``intrinsic_matrix``) or a flat object with ``width, height, fx, fy, cx, cy``.

    Returns the intrinsics and the depth units per metre when the file states a ``depth_scale``
    (values below 1 are read as metres per unit, e.g. 0.001; above 1 as units per metre, e.g.
    Open3D's 1000), else None.
    """
    path = Path(path)
    if not path.is_file():
        raise SourceError(f"intrinsics file {path} is missing; give an Open3D PinholeCameraIntrinsic JSON "
                          "or {width, height, fx, fy, cx, cy}")
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SourceError(f"intrinsics file {path} is not readable JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise SourceError(f"intrinsics file {path} holds no JSON object")
    try:
        if "intrinsic_matrix" in data:
            intr = Intrinsics.from_open3d_json(data, str(path))
        else:
            intr = Intrinsics(int(data["width"]), int(data["height"]), float(data["fx"]), float(data["fy"]),
                              float(data["cx"]), float(data["cy"]))
    except AssetError as exc:
        raise SourceError(str(exc)) from exc
    except (KeyError, ValueError, TypeError) as exc:
        raise SourceError(f"intrinsics file {path} lacks {exc}: expected Open3D's PinholeCameraIntrinsic "
                          "JSON or {width, height, fx, fy, cx, cy}") from exc
    if intr.width <= 0 or intr.height <= 0 or not (intr.fx > 0 and intr.fy > 0):
        raise SourceError(f"intrinsics file {path}: size and focal lengths must be positive, got {intr.width}x"
                          f"{intr.height} px, fx {intr.fx:g}, fy {intr.fy:g}; give the camera's calibration")
    if not all(np.isfinite((intr.fx, intr.fy, intr.cx, intr.cy))):
        raise SourceError(f"intrinsics file {path}: fx, fy, cx and cy must be finite numbers, got fx {intr.fx:g}, "
                          f"fy {intr.fy:g}, cx {intr.cx:g}, cy {intr.cy:g}; give the camera's calibration")
    scale = data.get("depth_scale")
    units = None
    if isinstance(scale, (int, float)) and scale > 0:
        units = 1.0 / float(scale) if scale < 1.0 else float(scale)
    return intr, units


def check_pair(depth: np.ndarray, color: np.ndarray | None, what: str,
               intrinsics: Intrinsics | None = None) -> str | None:
    """None when depth (H, W) and colour (H, W, 3) have the same size (and, given ``intrinsics``,
    the size the intrinsics describe), else the reason naming ``what``."""
    if color is not None and color.shape[:2] != depth.shape:
        return (f"{what}: depth {depth.shape[1]}x{depth.shape[0]} and colour {color.shape[1]}x{color.shape[0]} "
                "differ in size (swarmpose needs depth registered to colour)")
    if intrinsics is not None and depth.shape != (intrinsics.height, intrinsics.width):
        return (f"{what}: images are {depth.shape[1]}x{depth.shape[0]}, intrinsics "
                f"{intrinsics.width}x{intrinsics.height}; give the intrinsics of this camera mode")
    return None
