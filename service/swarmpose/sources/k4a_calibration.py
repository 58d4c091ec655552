"""Azure Kinect factory calibration (the ``calibration.json`` k4arecorder attaches to its MKV files).

The file holds per camera (``CALIBRATION_CameraPurposeDepth``, ``..PhotoVideo``) the
Brown-Conrady intrinsics of the full sensor, *normalised* by the sensor size with (0, 0) at
the corner of the top-left pixel, in the order ``cx, cy, fx, fy, k1..k6, codx, cody, p2, p1``,
and ``Rt``: the transform from the depth camera (the reference) to that camera, rotation
row-major, translation in metres. This module turns it into per-mode pixel intrinsics the way
the Azure Kinect SDK does (``transformation_get_mode_specific_camera_calibration``: scale by the
mode's binned sensor size, subtract the crop offset, then 0.5 to put (0, 0) at the pixel
centre) and into OpenCV's rational distortion vector ``[k1, k2, p1, p2, k3, k4, k5, k6]``,
which is the same model (k4a's Brown-Conrady projection equals OpenCV's rational model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SourceError

# mode -> (binned calibration resolution, crop offset, output resolution), from the Azure Kinect SDK
DEPTH_MODES: dict[str, tuple[tuple[int, int], tuple[int, int], tuple[int, int]]] = {
    "NFOV_2X2BINNED": ((512, 512), (96, 90), (320, 288)),
    "NFOV_UNBINNED": ((1024, 1024), (192, 180), (640, 576)),
    "WFOV_2X2BINNED": ((512, 512), (0, 0), (512, 512)),
    "WFOV_UNBINNED": ((1024, 1024), (0, 0), (1024, 1024)),
    "PASSIVE_IR": ((1024, 1024), (0, 0), (1024, 1024)),
}
COLOR_MODES: dict[int, tuple[tuple[int, int], tuple[int, int], tuple[int, int]]] = {  # by output height
    720: ((1280, 960), (0, 120), (1280, 720)),
    1080: ((1920, 1440), (0, 180), (1920, 1080)),
    1440: ((2560, 1920), (0, 240), (2560, 1440)),
    1536: ((2048, 1536), (0, 0), (2048, 1536)),
    2160: ((3840, 2880), (0, 360), (3840, 2160)),
    3072: ((4096, 3072), (0, 0), (4096, 3072)),
}
DEFAULT_MAX_RADIUS = 1.7
"""Normalised radius (tan of the off-axis angle) beyond which projections are not trusted when the
calibration states none (the colour camera's ``MetricRadius`` is 0)."""


@dataclass(frozen=True)
class CameraModel:
    """One camera in one mode.

    width, height: image size (px); K: (3, 3) pixel camera matrix, (0, 0) = centre of the
    top-left pixel; dist: (8,) OpenCV rational distortion [k1, k2, p1, p2, k3, k4, k5, k6];
    max_radius: normalised radius (x/z, y/z) within which the distortion model holds;
    R (3, 3), t (3,) m: x_this = R x_depth + t (depth camera = reference).
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    max_radius: float
    R: np.ndarray
    t: np.ndarray

    @property
    def pinhole(self) -> Intrinsics:
        """The pinhole part (distortion dropped) as swarmpose :class:`~swarmpose.core.camera.Intrinsics`."""
        k = self.K
        return Intrinsics(self.width, self.height, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))


def _camera(data: dict, purpose: str) -> dict:
    try:
        cams = data["CalibrationInformation"]["Cameras"]
    except (KeyError, TypeError) as exc:
        raise SourceError(f"Azure Kinect calibration lacks CalibrationInformation.Cameras ({exc})") from exc
    for cam in cams:
        if cam.get("Purpose") == purpose:
            return cam
    raise SourceError(f"Azure Kinect calibration has no {purpose} camera")


def _model(cam: dict, mode: tuple[tuple[int, int], tuple[int, int], tuple[int, int]],
           legacy_16_9: bool = False) -> CameraModel:
    try:
        p = np.asarray(cam["Intrinsics"]["ModelParameters"], dtype=np.float64)
        model_type = cam["Intrinsics"]["ModelType"]
        rot = np.asarray(cam["Rt"]["Rotation"], dtype=np.float64).reshape(3, 3)
        trans = np.asarray(cam["Rt"]["Translation"], dtype=np.float64).reshape(3)
        radius = float(cam.get("MetricRadius", 0.0))
    except (KeyError, ValueError, TypeError) as exc:
        raise SourceError(f"Azure Kinect calibration: camera {cam.get('Purpose')} is incomplete ({exc})") from exc
    if "BrownConrady" not in model_type or p.size < 14:
        raise SourceError(f"Azure Kinect calibration: unsupported lens model {model_type} with {p.size} parameters")
    cx, cy, fx, fy = p[:4]
    if legacy_16_9:  # old 16:9 colour calibrations: convert to 4:3 first, still normalised (as the SDK does)
        cy, fy = (cy * 2304 + 384) / 3072, fy * 2304 / 3072
    (bw, bh), (ox, oy), (w, h) = mode
    k = np.array([[fx * bw, 0.0, cx * bw - ox - 0.5], [0.0, fy * bh, cy * bh - oy - 0.5], [0.0, 0.0, 1.0]])
    k1, k2, k3, k4, k5, k6 = p[4:10]
    p2, p1 = p[12], p[13]
    dist = np.array([k1, k2, p1, p2, k3, k4, k5, k6])
    return CameraModel(w, h, k, dist, radius if radius > 0 else DEFAULT_MAX_RADIUS, rot, trans)


def depth_model(data: dict, depth_mode: str) -> CameraModel:
    """The depth camera in ``depth_mode`` (e.g. ``NFOV_UNBINNED``) from a parsed calibration.json."""
    if depth_mode not in DEPTH_MODES:
        raise SourceError(f"unknown Azure Kinect depth mode {depth_mode!r}; known: {sorted(DEPTH_MODES)}")
    return _model(_camera(data, "CALIBRATION_CameraPurposeDepth"), DEPTH_MODES[depth_mode])


def color_model(data: dict, height: int) -> CameraModel:
    """The colour camera for an image ``height`` px high (720, 1080, 1440, 1536, 2160 or 3072)."""
    if height not in COLOR_MODES:
        raise SourceError(f"no Azure Kinect colour mode is {height} px high; known: {sorted(COLOR_MODES)}")
    cam = _camera(data, "CALIBRATION_CameraPurposePhotoVideo")
    sw, sh = int(cam.get("SensorWidth", 4096)), int(cam.get("SensorHeight", 3072))
    return _model(cam, COLOR_MODES[height], legacy_16_9=sw * 9 // 16 == sh)


def depth_mode_for_size(width: int, height: int) -> str:
    """The depth mode of a depth image size (WFOV_UNBINNED for 1024x1024)."""
    for name, (_, _, size) in DEPTH_MODES.items():
        if size == (width, height):
            return name
    raise SourceError(f"no Azure Kinect depth mode produces {width}x{height} images")
