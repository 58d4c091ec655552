"""The 2D detector's crop boxes, held still while the person they frame stays where it was.

The detector looks at each tracked person in a square around the box of the joints tracked in
the last frame (:mod:`swarmpose.pipeline.step`). That closes a loop: a network's keypoints move
when its crop moves by a pixel (MoveNet's wrists by centimetres, measured on a person standing
still), the track follows the keypoints, and the next crop follows the track. On a still person
the loop turns the track's own jitter into more of it (issue 53: MoveNet's jitter on a still
synthetic person 8.3 -> 2.5 mm with the box held).

So a track's box is kept while every edge of its new joints box lies within ``share`` of the kept
box's larger side of the kept edge, and replaced by the new box as soon as one edge moves
farther. The crop square is 1.25 times the box's larger side, so a box held within 5 % still
frames the person; moving people move their box past the share within a frame or two.
"""

from __future__ import annotations

import numpy as np

BOX_HOLD_SHARE = 0.05
"""The default share (of the box's larger side) an edge may move while the box is held."""


class SteadyBoxes:
    """The crop box of each track id ([x0, y0, x1, y1] px), held while it moves less than ``share``
    (module doc); ``share`` 0: every box as given."""

    def __init__(self, share: float = BOX_HOLD_SHARE):
        if not (np.isfinite(share) and share >= 0):
            raise ValueError(f"a box hold share of {share}; it must be a number >= 0")
        self.share = float(share)
        self.held: dict[int, np.ndarray] = {}

    def update(self, boxes: dict[int, np.ndarray | None]) -> dict[int, np.ndarray]:
        """The boxes to detect in next, by track id, for the tracks' new joints boxes ``boxes`` (None:
        the track has none this frame). Tracks not in ``boxes``, or without a box, are forgotten."""
        out: dict[int, np.ndarray] = {}
        for key, box in boxes.items():
            if box is None:
                continue
            box = np.asarray(box, dtype=np.float64)
            kept = self.held.get(key)
            if kept is not None and self.share > 0 and np.all(np.isfinite(box)):
                side = max(kept[2] - kept[0], kept[3] - kept[1])
                if np.all(np.abs(box - kept) <= self.share * side):
                    box = kept
            out[key] = box
        self.held = out
        return dict(out)

    def reset(self) -> None:
        """Forget every box."""
        self.held = {}
