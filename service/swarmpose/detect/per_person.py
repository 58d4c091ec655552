"""The 2D detector run once per person found in the depth (:mod:`swarmpose.detect.people`).

Single-person networks (MoveNet, BlazePose) fix on one person per crop, and in a crowd the
crop around one person holds parts of its neighbours. So each person's detection runs on
the square around its segment's box with **the other people's pixels painted grey**
(:func:`masked_colour`): what is left in the crop is this person and the background. The
keypoints come back in frame pixels (the detectors map their crops back).

A detection whose keypoints mostly fall outside its own segment (a crop around a piece of
wall beside a person finds that person) is not this segment's: it is dropped, with a note
(:func:`on_segment_share`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from swarmpose.detect.joints import Detector, Joints2D
from swarmpose.detect.people import PersonSegment, Segmentation

MASK_GREY = 127
"""The colour (each channel, 0..255) other people's pixels are painted with in a person's crop."""
KEYPOINT_MIN_SCORE = 0.3
"""Keypoints below this score do not count in :func:`on_segment_share`."""
MIN_ON_SEGMENT = 0.5
"""A detection with fewer of its keypoints on its segment than this share is not the segment's."""
MIN_HINT_IOU = 0.3
"""A last-frame joints box frames a segment's person when it overlaps the segment's box this much."""
ON_SEGMENT_PX = 6
"""Keypoints within this many pixels of the segment's mask count as on it (edges, depth holes)."""


@dataclass(frozen=True)
class PersonDetection:
    """One person of one frame: its segment (None: found by the detector on the whole frame,
    without a segment) and its 2D joints (None when the detector failed, ``note`` says why; or
    when the detection was not this segment's, ``refused`` says why)."""

    segment: PersonSegment | None
    joints: Joints2D | None
    note: str = ""
    refused: str = ""


def masked_colour(color: np.ndarray, labels: np.ndarray, keep: int) -> np.ndarray:
    """A copy of ``color`` (H, W, 3) uint8 with every pixel of another person (``labels`` (H, W)
    int: 0 = nobody, k = person k) painted :data:`MASK_GREY`; person ``keep`` and the
    background untouched."""
    others = (labels != 0) & (labels != keep)
    out = color.copy()
    out[others] = MASK_GREY
    return out


def on_segment_share(joints: Joints2D, segment: PersonSegment) -> float:
    """Share (0..1) of the confident keypoints of ``joints`` within :data:`ON_SEGMENT_PX` of
    ``segment.mask``; 1 when none is confident (nothing to contradict the segment)."""
    kp = joints.keypoints
    ok = (kp[:, 2] >= KEYPOINT_MIN_SCORE) & np.all(np.isfinite(kp[:, :2]), axis=1)
    if not ok.any():
        return 1.0
    mask, r = segment.mask, ON_SEGMENT_PX
    h, w = mask.shape
    on = []
    for x, y in kp[ok, :2]:  # the square window of each keypoint (K <= 33): no full-frame dilation
        u, v = int(round(x)), int(round(y))
        on.append(0 <= x < w and 0 <= y < h and bool(mask[max(v - r, 0):v + r + 1, max(u - r, 0):u + r + 1].any()))
    return float(np.mean(on))


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of boxes ``a`` and ``b`` ([x0, y0, x1, y1] px)."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    inter = max(float(w), 0.0) * max(float(h), 0.0)
    union = float((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1])) - inter
    return inter / union if union > 0 else 0.0


def crop_boxes(segments: Sequence[PersonSegment], hints: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Where to detect each segment's person: a hint box (the last frame's tracked joints,
    [x0, y0, x1, y1] px) overlapping the segment's box by IoU >= :data:`MIN_HINT_IOU`, each
    hint given to one segment at most (best IoU first), else the segment's own box. A track's
    joints frame its person as the single-person tracker's feedback does, so one person in
    view is detected as with ``max_people`` 1."""
    boxes = [np.asarray(s.box, dtype=np.float64) for s in segments]
    pairs = sorted(((box_iou(np.asarray(h, float), b), k, i) for k, h in enumerate(hints)
                    for i, b in enumerate(boxes)), reverse=True)
    out, used = list(boxes), set()
    given: set[int] = set()
    for iou, k, i in pairs:
        if iou < MIN_HINT_IOU:
            break
        if k in used or i in given:
            continue
        out[i] = np.asarray(hints[k], dtype=np.float64)
        used.add(k)
        given.add(i)
    return out


def detect_each(detector: Detector, frame, segmentation: Segmentation,
                hints: Sequence[np.ndarray] = ()) -> tuple[PersonDetection, ...]:
    """The 2D joints of every person of ``segmentation`` on ``frame`` (a
    :class:`~swarmpose.sources.base.Frame`), in the order of ``segmentation.people``; each
    detected in its :func:`crop_boxes` box (``hints``: the boxes of the last frame's tracked bodies). A
    detector that throws on one person gives that person no joints and a note; the others go on."""
    out = []
    several = len(segmentation.people) > 1
    crops = crop_boxes(segmentation.people, hints)
    for k, segment in enumerate(segmentation.people, 1):
        seen = frame
        if several and frame.color is not None:
            seen = replace(frame, color=masked_colour(frame.color, segmentation.labels, k))
        try:
            joints = detector.detect(seen, crops[k - 1])
        except Exception as exc:  # one person's failure must not cost the others theirs
            out.append(PersonDetection(segment, None, f"detector failed on person {k}: {exc}"))
            continue
        share = on_segment_share(joints, segment)
        if share < MIN_ON_SEGMENT:
            out.append(PersonDetection(segment, None, refused=f"only {share:.0%} of its detection lies on it"))
        else:
            out.append(PersonDetection(segment, joints))
    return tuple(out)
