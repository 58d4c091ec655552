"""The 2D detector's crop boxes, held still while the person they frame stays where it was.

The detector looks at each tracked person in a square around the box of the joints tracked in
the last frame (:mod:`swarmpose.pipeline.step`). That closes a loop: a network's keypoints move
when its crop moves by a pixel (MoveNet's wrists by centimetres, measured on a person standing
still), the track follows the keypoints, and the next crop follows the track. On a still person
the loop turns the track's own jitter into more of it (issue 53: MoveNet's jitter on a still
synthetic person 8.3 -> 2.5 mm with the box held).

So once a track's joints box has stayed within ``share`` of its larger side (every edge) of where
it was :data:`STILL_FRAMES` frames running, the detector is given that box, the anchor, for as long
as the new boxes stay within ``share`` of it; the first box past it is given as it is and becomes
the new anchor. A moving person's box leaves the share within a frame or two and is never held
(holding a walker's box lagging a few pixels behind cost a side view's walk 1-13 mm over 2 seeds
at shares 0.01-0.05 when the hold began at once), and the crop square is 1.25 times the box's
larger side, so a held box still frames the person. Opt-in (``--box-hold 0.02``; 0, the default,
gives the joints box every frame): on a fragile moving cell (jumping jacks from behind, MoveNet)
the run's path changes with the crop, and 5 of 12 seeds fell into the mirrored facing with the
hold against 3 of 12 without (BENCHMARKS.md, issue 53).
"""

from __future__ import annotations

import numpy as np

STILL_FRAMES = 5
"""Frames a box must stay within the share of its anchor before the anchor is held."""


class SteadyBoxes:
    """The crop box of each track id ([x0, y0, x1, y1] px), held once still (module doc); ``share`` 0:
    every box as given."""

    def __init__(self, share: float, still_frames: int = STILL_FRAMES):
        if not (np.isfinite(share) and share >= 0) or still_frames < 0:
            raise ValueError(f"a box hold share of {share} after {still_frames} frames; both must be >= 0")
        self.share, self.still_frames = float(share), int(still_frames)
        self.anchors: dict[int, tuple[np.ndarray, int]] = {}  # id -> (anchor box, frames within its share)

    def update(self, boxes: dict[int, np.ndarray | None]) -> dict[int, np.ndarray]:
        """The boxes to detect in next, by track id, for the tracks' new joints boxes ``boxes`` (None:
        the track has none this frame). Tracks not in ``boxes``, or without a box, are forgotten."""
        out: dict[int, np.ndarray] = {}
        anchors: dict[int, tuple[np.ndarray, int]] = {}
        for key, box in boxes.items():
            if box is None:
                continue
            box = np.asarray(box, dtype=np.float64)
            anchor, still = self.anchors.get(key, (None, 0))
            if anchor is not None and self.share > 0 and np.all(np.isfinite(box)):
                side = max(anchor[2] - anchor[0], anchor[3] - anchor[1])
                if np.all(np.abs(box - anchor) <= self.share * side):
                    anchors[key] = (anchor, still + 1)
                    out[key] = anchor if still + 1 >= self.still_frames else box
                    continue
            anchors[key], out[key] = (box, 0), box
        self.anchors = anchors
        return dict(out)

    def reset(self) -> None:
        """Forget every box."""
        self.anchors = {}
