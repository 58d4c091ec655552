"""2D joint detections and the detector protocol.

A :class:`Joints2D` holds one frame's keypoints in a :class:`~swarmpose.body.skeleton.KeypointLayout`:
``keypoints`` (K, 3) = x px, y px, score in [0, 1]; a missing keypoint has score 0.
Every detector (``simulated``, ``onnx:MODEL``, ``openpose-json:DIR``) implements
:class:`Detector`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from swarmpose.body.skeleton import KeypointLayout


@dataclass(frozen=True)
class Joints2D:
    """One frame's 2D keypoints.

    layout: keypoint order; keypoints: (K, 3) float (x px, y px, score 0..1, 0 = missing);
    frame_index / timestamp_ns: the frame they were detected on (its capture time).
    """

    layout: KeypointLayout
    keypoints: np.ndarray
    frame_index: int
    timestamp_ns: int

    def by_point(self, min_score: float = 0.0) -> dict[str, tuple[float, float, float]]:
        """Body point name -> (x, y, score) for keypoints the body models with score > ``min_score``."""
        out = {}
        for point, (x, y, s) in zip(self.layout.points, self.keypoints):
            if point is not None and s > min_score and np.isfinite(x) and np.isfinite(y):
                out[point] = (float(x), float(y), float(s))
        return out

    def as_dict(self) -> dict[str, list[float]]:
        """Keypoint name -> [x, y, score] (for JSON)."""
        return {n: [round(float(v), 3) for v in row] for n, row in zip(self.layout.keypoints, self.keypoints)}


class Detector(Protocol):
    """A 2D joint detector: ``detect(frame)`` returns the keypoints of the (single) person."""

    name: str
    layout: KeypointLayout

    def detect(self, frame, box: np.ndarray | None = None) -> Joints2D:
        """Keypoints on ``frame`` (a :class:`~swarmpose.sources.base.Frame`).

        box: optional (4,) [x0, y0, x1, y1] px where the person is expected (from the track
        or the previous detection); detectors that crop use it, others ignore it.
        """
        ...

    def close(self) -> None:
        """Release the model or files."""
        ...
