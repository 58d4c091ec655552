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
MIN_RADIUS_PX = 8.0
"""Alignment points closer than this give no region."""
MAX_REGIONS = 32
"""A frame keeps at most this many regions (its people; a frame index given again adds to the same frame)."""
SIDE_RATIO = (0.5, 3.0)
"""A region serves a box whose square's side is within this ratio of its own (a body bent over or
seated keeps its circle while its joints' box shrinks)."""


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


def aligned_square(centre: np.ndarray, rim: np.ndarray, scale: float = ROI_SCALE) -> TurnedSquare | None:
    """The region of a body from its alignment points (px): the hips' ``centre`` (2,) and the point
    ``rim`` (2,) on the circle around the body along its axis; None when they are not finite or the
    circle's radius is under :data:`MIN_RADIUS_PX` (no person's crop)."""
    centre, rim = np.asarray(centre, float), np.asarray(rim, float)
    axis = rim - centre
    radius = float(np.hypot(*axis))
    if not (np.all(np.isfinite(axis)) and radius >= MIN_RADIUS_PX):
        return None
    up = axis / radius
    return TurnedSquare((float(centre[0]), float(centre[1])), 2.0 * radius * scale, (float(up[0]), float(up[1])))


class RegionMemory:
    """The regions a network's detections gave, for the next frame's crops: a frame is cropped from the
    regions of the frame detected before it (one per detection with a person there), never from its own,
    so the people of one frame and a second pass on it do not crop each other's. ``begin(stamp)``
    starts a frame (a new ``stamp``: the one before becomes the last; a smaller one, a recording that
    started over, forgets them); ``add`` keeps a region of this frame (at most :data:`MAX_REGIONS`)."""

    def __init__(self, side_ratio: tuple[float, float] = SIDE_RATIO):
        self.side_ratio = side_ratio
        self._stamp: int | None = None
        self._last: list[TurnedSquare] = []
        self._now: list[TurnedSquare] = []

    def begin(self, stamp: int) -> None:
        """Start detecting frame ``stamp`` (the same stamp again: the same frame)."""
        if stamp == self._stamp:
            return
        went_back = self._stamp is not None and stamp < self._stamp
        self._stamp, self._last, self._now = stamp, [] if went_back else self._now, []

    @property
    def last(self) -> tuple[TurnedSquare, ...]:
        """The regions of the frame before this one, newest first."""
        return tuple(self._last)

    def region_for(self, box: np.ndarray | None, square_side: float) -> TurnedSquare | None:
        """The last frame's region to crop for ``box`` [x0, y0, x1, y1] px whose crop square has
        ``square_side`` px: of those centred in the box and within :attr:`side_ratio` of that side, the
        one centred nearest the box's centre; without a box, the newest; None where none is."""
        if box is None:
            return self._last[0] if self._last else None
        lo, hi = self.side_ratio
        middle = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
        fits = [r for r in self._last if box[0] <= r.centre[0] <= box[2] and box[1] <= r.centre[1] <= box[3]
                and lo <= r.side / square_side <= hi]
        return min(fits, key=lambda r: float(np.hypot(*(np.asarray(r.centre) - middle))), default=None)

    def add(self, region: TurnedSquare) -> None:
        """Keep ``region``, found on this frame, for the next."""
        self._now.insert(0, region)
        del self._now[MAX_REGIONS:]

    def discard(self, region: TurnedSquare | None) -> None:
        """Drop ``region``, found on this frame (a pass whose keypoints were not kept); None: nothing."""
        if region is not None and region in self._now:
            self._now.remove(region)

    def drop(self, region: TurnedSquare | None) -> None:
        """Drop ``region`` of the last frame (its crop found nobody); None: nothing."""
        if region is not None and region in self._last:
            self._last.remove(region)

    def clear(self) -> None:
        """Forget every region."""
        self._last, self._now = [], []
