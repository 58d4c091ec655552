"""A simulated 2D joint detector: ground truth plus a documented, seeded noise model.

For each frame, with ``s`` = the person's size in pixels (the larger side of the box
around all of the body's projected named points):

* **jitter**: every keypoint moves by Gaussian noise of std ``jitter * s`` per axis;
* **hip bias**: hip keypoints (and mid_hip) move ``hip_bias * s`` towards the neck, as
  human annotators and networks place hips higher than the joint centres;
* **outliers**: with probability ``outlier_rate`` a keypoint is replaced by a point
  uniformly within ``outlier_scale * s`` of the truth (score drawn from U(0.2, 0.6));
* **swaps**: with probability ``swap_rate`` per frame one random left/right pair of the
  layout swaps places (scores unchanged);
* **missing**: with probability ``missing_rate`` a keypoint is missing, and keypoints
  outside the image or behind the camera are always missing: reported as ``[0, 0, 0]``.
Inlier scores are drawn from U(0.6, 1.0). The generator is seeded per (seed, frame).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from swarmpose.body.skeleton import LAYOUTS, KeypointLayout
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import DetectorError
from swarmpose.detect.joints import Joints2D


@dataclass(frozen=True)
class SimulatedNoise:
    """Noise parameters; fractions of the person's size in pixels, or probabilities."""

    jitter: float = 0.01
    hip_bias: float = 0.03
    outlier_rate: float = 0.02
    outlier_scale: float = 0.15
    swap_rate: float = 0.01
    missing_rate: float = 0.03

    def as_dict(self) -> dict:
        """The parameters, for writing next to a sequence."""
        return asdict(self)


HIP_POINTS = ("left_hip", "right_hip", "mid_hip")


def person_size(points2d: np.ndarray) -> float:
    """Larger side (px) of the box around finite projected points (N, 2)."""
    ok = np.all(np.isfinite(points2d), axis=1)
    if not np.any(ok):
        return 0.0
    return float(np.max(np.ptp(points2d[ok], axis=0)))


def _lr_pairs(layout: KeypointLayout) -> list[tuple[int, int]]:
    names = layout.keypoints
    return [(i, names.index("right_" + n[5:])) for i, n in enumerate(names)
            if n.startswith("left_") and "right_" + n[5:] in names]


def simulate_detections(layout: KeypointLayout, points: dict[str, np.ndarray], depth_ok: dict[str, bool],
                        size_px: float, intrinsics: Intrinsics, noise: SimulatedNoise, seed: int, frame: int,
                        stream: int = 0) -> dict[str, list[float]]:
    """One frame of detections: keypoint name -> [x, y, score] (pixels; score 0 = missing).

    points: body point name -> true pixel position (2,); depth_ok: point -> seen (in front
    of the camera and not hidden by another person; False = always missing); size_px: the
    person's size in pixels (see :func:`person_size`); stream: the person's 0-based index in
    a scene, so each person of a frame draws its own noise (0 = the single-person draws).
    """
    rng = np.random.default_rng([seed, frame] if stream == 0 else [seed, frame, stream])
    n = len(layout.keypoints)
    xy = np.zeros((n, 2))
    present = np.zeros(n, dtype=bool)
    neck = points.get("neck")
    for i, point in enumerate(layout.points):
        if point is None or point not in points:
            continue
        xy[i] = points[point]
        present[i] = depth_ok.get(point, True)
        if point in HIP_POINTS and neck is not None:
            d = neck - xy[i]
            xy[i] += noise.hip_bias * size_px * d / max(np.linalg.norm(d), 1e-9)
    # Draw every random number for every keypoint, so one keypoint's fate never shifts another's.
    jitter = rng.standard_normal((n, 2)) * noise.jitter * size_px
    is_outlier = rng.random(n) < noise.outlier_rate
    outlier_offset = (rng.random((n, 2)) * 2 - 1) * noise.outlier_scale * size_px
    is_missing = rng.random(n) < noise.missing_rate
    score = np.where(is_outlier, rng.uniform(0.2, 0.6, n), rng.uniform(0.6, 1.0, n))
    swap_draw, swap_pick = rng.random(), rng.random()
    xy = np.where(is_outlier[:, None], xy + outlier_offset, xy + jitter)
    pairs = _lr_pairs(layout)
    if pairs and swap_draw < noise.swap_rate:
        a, b = pairs[int(swap_pick * len(pairs))]
        xy[[a, b]] = xy[[b, a]]
        present[[a, b]] = present[[b, a]]
    inside = ((xy[:, 0] >= 0) & (xy[:, 0] <= intrinsics.width - 1)
              & (xy[:, 1] >= 0) & (xy[:, 1] <= intrinsics.height - 1))
    ok = present & ~is_missing & inside
    return {name: ([float(xy[i, 0]), float(xy[i, 1]), float(score[i])] if ok[i] else [0.0, 0.0, 0.0])
            for i, name in enumerate(layout.keypoints)}


class SimulatedDetector:
    """``--detector simulated``: the noise model above applied to a source's ground truth.

    ground_truth: the sequence's :class:`~swarmpose.sources.groundtruth.GroundTruth` (a
    folder or ``utdmhad:`` source's ``.ground_truth``). ``detect(frame)`` returns keypoints
    (K, 3) x px, y px, score: those ``swarmpose synth`` recorded for ``frame.index``, or,
    where the ground truth records none but holds true 2D points (``points2d``, e.g. a
    UTD-MHAD Kinect skeleton), COCO-17 keypoints drawn from them now with
    :class:`SimulatedNoise` defaults (seeded by ``seed`` and the frame; keypoints of points
    the ground truth lacks, such as the face, are missing).

    With one person ``box`` is ignored. On a frame of several people (the ground truth's
    ``people``), ``detect(frame, box)`` returns the person the box is around (see
    :func:`match_person`); without a box, person 1's; a box around nobody gets every keypoint
    missing. :meth:`detect_people` returns every visible person's detections with its id.
    """

    def __init__(self, ground_truth, source_name: str = "the source", seed: int = 0):
        if ground_truth is None:
            raise DetectorError(f"--detector simulated needs a `swarmpose synth` sequence folder with "
                                f"groundtruth.jsonl (or a utdmhad: file) as --source; {source_name} has no ground "
                                "truth. Use --detector onnx:MODEL.onnx or --detector openpose-json:DIR for other "
                                "sources")
        self.ground_truth = ground_truth
        self.name = "simulated"
        self.source_name = source_name
        self.seed = int(seed)
        self._people = getattr(ground_truth, "people", ())
        layouts = {d[0] for d in ground_truth.detections if d is not None}
        layouts |= {p.detection[0] for frame in self._people for p in frame if p.detection is not None}
        self.from_points = not layouts and bool(ground_truth.points2d)
        if self.from_points:
            self.layout = LAYOUTS["coco17"]
            return
        if not layouts:
            raise DetectorError(f"the ground truth of {source_name} records no simulated detections; "
                                "re-run `swarmpose synth` to rewrite the sequence")
        if len(layouts) > 1:
            raise DetectorError(f"the ground truth of {source_name} mixes keypoint layouts {sorted(layouts)}")
        self.layout = LAYOUTS[layouts.pop()]

    def _row(self, frame) -> int:
        try:
            return self.ground_truth.row(int(frame.index))
        except KeyError:
            raise DetectorError(f"simulated: {self.source_name} has no ground-truth record for frame "
                                f"{frame.index}") from None

    def _joints(self, frame, detection) -> Joints2D:
        keypoints = (np.zeros((len(self.layout.keypoints), 3)) if detection is None
                     else np.array(detection[1], dtype=np.float64))
        return Joints2D(self.layout, keypoints, int(frame.index), int(frame.timestamp_ns))

    def detect(self, frame, box: np.ndarray | None = None) -> Joints2D:
        """The recorded detections of ``frame.index`` as :class:`~swarmpose.detect.joints.Joints2D`:
        of the person ``box`` (4,) [x0, y0, x1, y1] px is around when the frame has several."""
        row = self._row(frame)
        people = self._people[row] if self._people else ()
        if len(people) > 1 and box is not None:
            k = match_person(people, _checked_box(box), frame.intrinsics)
            return self._joints(frame, None if k is None else people[k].detection)
        if self.from_points:
            points = self.ground_truth.points2d[row]
            size = person_size(np.array(list(points.values()), dtype=np.float64).reshape(-1, 2))
            drawn = simulate_detections(self.layout, points, {}, size, frame.intrinsics, SimulatedNoise(),
                                        self.seed, int(frame.index))
            keypoints = np.array([drawn[k] for k in self.layout.keypoints], dtype=np.float64)
            return Joints2D(self.layout, keypoints, int(frame.index), int(frame.timestamp_ns))
        return self._joints(frame, self.ground_truth.detections[row])

    def detect_people(self, frame) -> list[tuple[int, Joints2D]]:
        """Every visible person's detections on ``frame`` with its true id (1..P), in id order;
        a single-person sequence gives ``[(1, detect(frame))]``."""
        row = self._row(frame)
        people = self._people[row] if self._people else ()
        if not people:
            return [(1, self.detect(frame))]
        return [(p.id, self._joints(frame, p.detection)) for p in people if p.visible > 0]

    def close(self) -> None:
        """Nothing to release."""


def _checked_box(box) -> np.ndarray:
    b = np.asarray(box, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] < b[0] or b[3] < b[1]:
        raise DetectorError(f"simulated: box must be [x0, y0, x1, y1] px with x0 <= x1 and y0 <= y1, got {box!r}")
    return b


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boxes (4,) [x0, y0, x1, y1] px, inclusive pixel bounds."""
    w = min(a[2], b[2]) - max(a[0], b[0]) + 1
    h = min(a[3], b[3]) - max(a[1], b[1]) + 1
    inter = max(w, 0.0) * max(h, 0.0)
    area = (a[2] - a[0] + 1) * (a[3] - a[1] + 1) + (b[2] - b[0] + 1) * (b[3] - b[1] + 1) - inter
    return float(inter / area) if area > 0 else 0.0


def match_person(people, box: np.ndarray, intrinsics: Intrinsics) -> int | None:
    """Index into ``people`` (objects with ``joints2d`` (J, 2) px, ``joints3d`` (J, 3),
    ``occluded`` (J,) bool and ``box`` (4,) or None) of the person ``box`` (4,) is around.

    Each person scores the share of its visible true joints (in front of the camera, inside
    the image, not hidden by another person) that lie inside ``box``; the largest share wins,
    ties go to the larger IoU of ``box`` with the person's visible-pixel box, then to the
    lower index. None when no visible joint of anyone lies in ``box`` and no box overlaps it.
    """
    best, best_key = None, (0.0, 0.0)
    for k, person in enumerate(people):
        xy = np.asarray(person.joints2d, dtype=np.float64)
        seen = (np.all(np.isfinite(xy), axis=1) & (np.asarray(person.joints3d)[:, 2] > 0)
                & ~np.asarray(person.occluded, dtype=bool)
                & (xy[:, 0] >= 0) & (xy[:, 0] <= intrinsics.width - 1)
                & (xy[:, 1] >= 0) & (xy[:, 1] <= intrinsics.height - 1))
        inside = seen & (xy[:, 0] >= box[0]) & (xy[:, 0] <= box[2]) & (xy[:, 1] >= box[1]) & (xy[:, 1] <= box[3])
        share = float(inside.sum() / seen.sum()) if seen.any() else 0.0
        iou = 0.0 if person.box is None else box_iou(box, np.asarray(person.box, dtype=np.float64))
        key = (round(share, 9), iou)
        if key > best_key:
            best, best_key = k, key
    return best
