"""A pose network's region of interest turned with the body: the crop BlazePose's landmark model expects.

BlazePose's landmark network was trained on square crops centred on the hips and turned so that the
body's axis points up, sized by a circle around the whole body (MediaPipe's alignment-point ROI). It
returns, besides its 33 landmarks, the two alignment points of that crop for the next frame: the hips'
centre (row 33) and a point on the circle straight along the body's axis (row 34). The square is
:data:`ROI_SCALE` times the circle's diameter. A crop cut square to the image around the person's box
instead, as for MoveNet, shows a bent-over or seated body turned and off-centre.

Coordinates: frame pixels with pixel centres at integers (as :class:`~swarmpose.detect.joints.Joints2D`);
a crop of ``size`` pixels runs 0..size from its edge, so its centre is at size / 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ROI_SCALE = 1.25
"""The crop's side over the alignment circle's diameter (MediaPipe's pose ROI scale)."""


@dataclass(frozen=True)
class TurnedSquare:
    """A square region of the frame: ``centre`` (2,) px, ``side`` px and ``up`` (2,), the unit vector
    in the frame (x right, y down) that points up in the crop."""

    centre: tuple[float, float]
    side: float
    up: tuple[float, float]

    def _axes(self) -> np.ndarray:
        """(2, 2): columns are the crop's x (right) and y (down) axes in the frame."""
        down = -np.asarray(self.up, float)
        return np.stack([np.array([down[1], -down[0]]), down], axis=1)

    def crop(self, image: np.ndarray, size: int) -> np.ndarray:
        """The region of ``image`` (H, W, 3) uint8 as (size, size, 3) uint8, bilinear, black outside the image."""
        import cv2

        to_crop = (size / self.side) * self._axes().T  # crop px = size/2 - 0.5 + A @ (frame px - centre)
        shift = (size / 2 - 0.5) - to_crop @ np.asarray(self.centre, float)
        matrix = np.hstack([to_crop, shift[:, None]])
        return cv2.warpAffine(image, matrix, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0)

    def to_frame(self, xy: np.ndarray, size: int) -> np.ndarray:
        """Crop coordinates (N, 2) (0..size from the crop's edge) -> frame pixels (N, 2)."""
        offset = (np.asarray(xy, float) - size / 2) * (self.side / size)
        return np.asarray(self.centre, float) + offset @ self._axes().T

    def holds(self, point: np.ndarray) -> bool:
        """Whether frame pixel ``point`` (2,) lies inside the region."""
        local = (np.asarray(point, float) - self.centre) @ self._axes()
        return bool(np.all(np.abs(local) <= self.side / 2))


def aligned_square(centre: np.ndarray, rim: np.ndarray, scale: float = ROI_SCALE) -> TurnedSquare | None:
    """The region of a body from its alignment points (px): the hips' ``centre`` (2,) and the point
    ``rim`` (2,) on the circle around the body along its axis; None when they coincide or are not finite."""
    centre, rim = np.asarray(centre, float), np.asarray(rim, float)
    axis = rim - centre
    radius = float(np.hypot(*axis))
    if not (np.all(np.isfinite(axis)) and radius > 1.0):
        return None
    up = axis / radius
    return TurnedSquare((float(centre[0]), float(centre[1])), 2.0 * radius * scale, (float(up[0]), float(up[1])))
