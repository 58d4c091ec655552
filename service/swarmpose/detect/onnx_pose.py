"""2D joint detectors running ONNX pose networks with onnxruntime (CPU).

Two network families are supported, chosen from the model's input and output shapes
(or forced with ``adapter="movenet"`` / ``"blazepose"``):

* **MoveNet single-pose** (``movenet``): input ``[1, 192, 192, 3]`` uint8 or int32 RGB;
  output ``[1, 1, 17, 3]`` = (y, x, score) normalised to the input square, COCO-17 order.
  Layout ``coco17``.
* **BlazePose full landmark** (``blazepose``): input ``[1, 256, 256, 3]`` float32 RGB 0..1
  of a person crop; output ``[1, 195]`` = 39 x (x, y, z, visibility, presence) in crop
  pixels, of which the first 33 are the BlazePose landmarks, and a ``[1, 1]`` pose flag
  (probability that a person is in the crop). Layout ``blazepose33``. Visibility is a logit:
  the keypoint score is ``sigmoid(visibility)`` (on a real photo the raw values run 1.7..12.5,
  the sigmoid 0.85..1.0 with the lowest on occluded joints). When the pose flag is below
  ``min_pose_flag`` every keypoint is reported missing (score 0).

Crops
-----
Every network sees a square region of the frame, enlarged where it leaves the image with
black padding, resized to the network's input:

* MoveNet: with a ``box`` ([x0, y0, x1, y1] px), the square around it enlarged by
  ``margin`` (default 1.25); without, the whole frame padded to a square (centred).
* BlazePose: the region its detection of that person on the frame before gave (its alignment
  points: the hips' centre and the body's circle, a square 1.25x the circle turned with the body's
  axis, :mod:`swarmpose.detect.regions`), as MediaPipe's tracking mode crops; with a ``box``, of
  the last frame's regions centred in the box and of about its size the one nearest its centre,
  else the square around the box enlarged by ``margin`` (default 1.25); without a box, the last
  frame's newest region; without either (first frame, a recording started over, or after the pose
  flag said nobody was in the last region), the whole frame padded to a square.

Where a network would see the whole frame (no box, nothing to follow), it runs twice when
``refine`` is on (the default): once on the whole frame, then on the square around the
keypoints it found there (score > ``REFINE_MIN_SCORE``), keeping the pass with the higher
mean keypoint score. A person who fills a fifth of a
640x480 frame covers ~40 of MoveNet's 192 input pixels in the first pass and most of them in
the second, which is where its keypoints become usable. The
second pass costs one inference, on the first frame and after a loss only.

Keypoints come back in frame pixels (the centre of the top-left pixel at (0, 0)).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import BLAZEPOSE33, COCO17, KeypointLayout
from swarmpose.core.errors import DetectorError
from swarmpose.detect.joints import Joints2D
from swarmpose.detect.regions import RegionMemory, TurnedSquare, aligned_square

DEFAULT_MARGIN = 1.25
"""A box is enlarged by this factor (on its larger side) into the square the network sees."""

REFINE_MIN_SCORE = 0.2
"""Keypoints of a whole-frame pass above this score define the crop of the second pass."""

ALIGNMENT_ROWS = (33, 34)
"""BlazePose's landmark rows of the hips' centre and the body circle's point along its axis."""


def default_threads() -> int:
    """onnxruntime intra-op threads: half the cores (at least 1, at most 4).

    The detector runs beside the tracker (its own thread, see
    :class:`~swarmpose.detect.thread.DetectorThread`), so on a 2-core machine it takes one.
    """
    return max(1, min(4, (os.cpu_count() or 2) // 2))


@dataclass(frozen=True)
class Square:
    """A square region of the frame: top-left corner ``x0``, ``y0`` (pixel edges, px) and ``side`` px.

    Frame pixel (x, y) (pixel centres) lies at ((x + 0.5 - x0) / side, (y + 0.5 - y0) / side)
    in the square's normalised coordinates.
    """

    x0: int
    y0: int
    side: int

    def to_frame(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Normalised square coordinates (N,) each, 0..1 -> frame pixels (N, 2)."""
        return np.stack([self.x0 + u * self.side - 0.5, self.y0 + v * self.side - 0.5], axis=-1)


def square_around(box, margin: float = DEFAULT_MARGIN) -> Square:
    """The square (px) centred on ``box`` [x0, y0, x1, y1] whose side is ``margin`` x its larger side."""
    x0, y0, x1, y1 = (float(v) for v in box)
    side = max(x1 - x0, y1 - y0) * margin
    if not np.isfinite(side) or side < 2:
        raise DetectorError(f"cannot crop around box {list(box)}: it must be [x0, y0, x1, y1] with x1 > x0, y1 > y0")
    side_px = int(np.ceil(side))
    return Square(int(round((x0 + x1) / 2 - side_px / 2)), int(round((y0 + y1) / 2 - side_px / 2)), side_px)


def whole_frame(width: int, height: int) -> Square:
    """The frame padded (centred) to a square of its larger side."""
    return square_around((0, 0, width, height), 1.0)


def crop_square(image: np.ndarray, square: Square, size: int) -> np.ndarray:
    """The ``square`` of ``image`` (H, W, 3) uint8, black outside the image, resized to (size, size, 3) uint8."""
    import cv2

    h, w = image.shape[:2]
    s = square.side
    out = np.zeros((s, s, 3), np.uint8)
    xa, ya = max(square.x0, 0), max(square.y0, 0)
    xb, yb = min(square.x0 + s, w), min(square.y0 + s, h)
    if xb > xa and yb > ya:
        out[ya - square.y0:yb - square.y0, xa - square.x0:xb - square.x0] = image[ya:yb, xa:xb]
    if s == size:
        return out
    return cv2.resize(out, (size, size), interpolation=cv2.INTER_AREA if s > size else cv2.INTER_LINEAR)


def keypoint_box(keypoints: np.ndarray, min_score: float) -> np.ndarray | None:
    """[x0, y0, x1, y1] px around keypoints (K, 3) with score > ``min_score``; None when fewer than 2."""
    ok = (keypoints[:, 2] > min_score) & np.all(np.isfinite(keypoints[:, :2]), axis=1)
    if ok.sum() < 2:
        return None
    xy = keypoints[ok, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    if np.any(hi - lo < 2):
        return None
    return np.array([lo[0], lo[1], hi[0], hi[1]])


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60, 60)))


@dataclass(frozen=True)
class _Port:
    name: str
    shape: tuple
    type: str


class _Adapter:
    """What a network remembers between detections: here nothing (a detection without a box sees the
    whole frame). ``begin(stamp)`` starts a frame's detections; ``found`` is the region the last run
    remembered (None: none), ``discard`` drops it, ``forget`` drops all."""

    follows = False
    found: TurnedSquare | None = None

    def begin(self, stamp: object) -> None:
        """Start the detections of frame ``stamp``."""

    def discard(self, region: TurnedSquare | None) -> None:
        """Drop a region this frame's run remembered."""

    def forget(self) -> None:
        """Forget what earlier detections left."""


class _MoveNet(_Adapter):
    """MoveNet single-pose: whole frame or box -> (17, 3) COCO keypoints."""

    name = "movenet"
    layout = COCO17
    size = 192

    @staticmethod
    def matches(inputs: list[_Port], outputs: list[_Port]) -> bool:
        return (len(inputs) == 1 and inputs[0].shape == (1, 192, 192, 3)
                and inputs[0].type in ("tensor(uint8)", "tensor(int32)")
                and any(o.shape == (1, 1, 17, 3) for o in outputs))

    def __init__(self, inputs: list[_Port], outputs: list[_Port], margin: float):
        self.input = inputs[0].name
        self.dtype = np.uint8 if inputs[0].type == "tensor(uint8)" else np.int32
        self.output = next(o.name for o in outputs if o.shape == (1, 1, 17, 3))
        self.margin = margin

    def run(self, session, image: np.ndarray, box: np.ndarray | None) -> np.ndarray:
        h, w = image.shape[:2]
        square = whole_frame(w, h) if box is None else square_around(box, self.margin)
        tensor = crop_square(image, square, self.size)[None].astype(self.dtype)
        out = session.run([self.output], {self.input: tensor})[0].reshape(17, 3).astype(np.float64)
        xy = square.to_frame(out[:, 1], out[:, 0])
        return np.concatenate([xy, np.clip(out[:, 2:3], 0.0, 1.0)], axis=1)


class _BlazePose(_Adapter):
    """BlazePose full landmark: person crop -> (33, 3) BlazePose keypoints; each person's next crop is
    the region its alignment points gave (:class:`~swarmpose.detect.regions.RegionMemory`)."""

    name = "blazepose"
    layout = BLAZEPOSE33
    size = 256

    @staticmethod
    def matches(inputs: list[_Port], outputs: list[_Port]) -> bool:
        return (len(inputs) == 1 and inputs[0].shape == (1, 256, 256, 3) and inputs[0].type == "tensor(float)"
                and any(o.shape == (1, 195) for o in outputs) and any(o.shape == (1, 1) for o in outputs))

    def __init__(self, inputs: list[_Port], outputs: list[_Port], margin: float, min_pose_flag: float = 0.5):
        self.input = inputs[0].name
        self.landmarks = next(o.name for o in outputs if o.shape == (1, 195))
        self.flag = next(o.name for o in outputs if o.shape == (1, 1))
        self.margin = margin
        self.min_pose_flag = min_pose_flag
        self.regions = RegionMemory()

    @property
    def follows(self) -> bool:
        """Whether a detection without a box crops the last frame's region (else the whole frame)."""
        return bool(self.regions.last)

    def begin(self, stamp: object) -> None:
        self.regions.begin(stamp)

    def discard(self, region: TurnedSquare | None) -> None:
        self.regions.discard(region)

    def forget(self) -> None:
        self.regions.clear()

    def run(self, session, image: np.ndarray, box: np.ndarray | None) -> np.ndarray:
        h, w = image.shape[:2]
        square = whole_frame(w, h) if box is None else square_around(box, self.margin)
        region = self.regions.region_for(box, square.side)
        tensor = crop_square(image, square, self.size) if region is None else region.crop(image, self.size)
        landmarks, flag = session.run([self.landmarks, self.flag],
                                      {self.input: tensor[None].astype(np.float32) / 255.0})
        lm = landmarks.reshape(39, 5).astype(np.float64)
        if region is None:
            xy = square.to_frame(lm[:, 0] / self.size, lm[:, 1] / self.size)
        else:
            xy = region.to_frame(lm[:, :2], self.size)
        self.found = None
        if float(np.ravel(flag)[0]) < self.min_pose_flag:  # nobody there: not that region again
            self.regions.drop(region)
            return np.zeros((33, 3))
        self.found = aligned_square(xy[ALIGNMENT_ROWS[0]], xy[ALIGNMENT_ROWS[1]])
        if self.found is not None:
            self.regions.add(self.found)
        return np.concatenate([xy[:33], _sigmoid(lm[:33, 3:4])], axis=1)


ADAPTERS = {a.name: a for a in (_MoveNet, _BlazePose)}
SUPPORTED = ("movenet: input [1,192,192,3] uint8/int32, output [1,1,17,3]; "
             "blazepose: input [1,256,256,3] float32, outputs [1,195] and [1,1]")


class OnnxPoseDetector:
    """A single-person 2D detector running an ONNX pose network on the frame's colour image.

    model: path of the ``.onnx`` file; adapter: ``"movenet"``, ``"blazepose"`` or None (pick
    from the model's shapes); threads: onnxruntime intra-op threads (None:
    :func:`default_threads`); margin: box enlargement into the crop square; refine: a
    whole-frame detection is followed by a second pass on the crop around what it found.
    ``detect(frame, box)`` returns :class:`Joints2D` in frame pixels (see the module doc for crops).
    Raises :class:`DetectorError` naming the file for a missing or unreadable model, or one
    whose shapes no adapter supports.
    """

    def __init__(self, model: str | Path, adapter: str | None = None, threads: int | None = None,
                 margin: float = DEFAULT_MARGIN, refine: bool = True):
        import onnxruntime as ort

        self.path = Path(model).expanduser()
        if not self.path.is_file():
            raise DetectorError(f"ONNX model {self.path} not found; pass onnx:PATH to a .onnx pose model")
        if adapter is not None and adapter not in ADAPTERS:
            raise DetectorError(f"unknown ONNX adapter {adapter!r} for {self.path}; choose one of {sorted(ADAPTERS)}")
        if not (margin >= 1.0 and np.isfinite(margin)):
            raise DetectorError(f"crop margin must be a number >= 1, got {margin}")
        self.threads = int(threads) if threads is not None else default_threads()
        if self.threads < 1:
            raise DetectorError(f"ONNX threads must be at least 1, got {threads}")
        options = ort.SessionOptions()
        options.intra_op_num_threads = self.threads
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 3
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")  # do not busy-wait beside the tracker
        try:
            self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types for unreadable models
            raise DetectorError(f"cannot load ONNX model {self.path}: {str(exc).strip().splitlines()[0]}") from exc
        inputs = [_Port(i.name, tuple(i.shape), i.type) for i in self.session.get_inputs()]
        outputs = [_Port(o.name, tuple(o.shape), o.type) for o in self.session.get_outputs()]
        found = (f"inputs {[(p.shape, p.type) for p in inputs]}, outputs {[p.shape for p in outputs]}")
        if adapter is None:
            chosen = next((a for a in ADAPTERS.values() if a.matches(inputs, outputs)), None)
            if chosen is None:
                raise DetectorError(f"ONNX model {self.path} has {found}; no supported pose network has these "
                                    f"shapes (supported: {SUPPORTED})")
        else:
            chosen = ADAPTERS[adapter]
            if not chosen.matches(inputs, outputs):
                raise DetectorError(f"ONNX model {self.path} has {found}, not what adapter {adapter!r} needs "
                                    f"(supported: {SUPPORTED})")
        self.adapter = chosen(inputs, outputs, margin)
        self.refine = bool(refine)
        self.layout: KeypointLayout = chosen.layout
        self.name = f"onnx:{self.path.name}"

    def detect(self, frame, box: np.ndarray | None = None) -> Joints2D:
        """Keypoints (K, 3) x px, y px, score of the person in ``frame.color`` (inside ``box`` when given)."""
        if self.session is None:
            raise DetectorError(f"{self.name} is closed")
        image = frame.color
        if image is None:
            raise DetectorError(f"{self.name} needs colour images; frame {frame.index} has none")
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise DetectorError(f"{self.name} needs (H, W, 3) uint8 RGB, frame {frame.index} has "
                                f"{image.shape} {image.dtype}")
        box = None if box is None else np.asarray(box, dtype=np.float64).reshape(4)
        try:
            self.adapter.begin(frame.index)
            whole = box is None and not self.adapter.follows
            keypoints = self.adapter.run(self.session, image, box)
            found = keypoint_box(keypoints, REFINE_MIN_SCORE) if whole and self.refine else None
            if found is not None:
                first = self.adapter.found
                refined = self.adapter.run(self.session, image, found)
                if refined[:, 2].mean() >= keypoints[:, 2].mean():  # the next frame follows the pass kept
                    keypoints = refined
                    self.adapter.discard(first)
                else:
                    self.adapter.discard(self.adapter.found)
        except DetectorError:
            raise
        except Exception as exc:
            raise DetectorError(f"{self.name} failed on frame {frame.index}: {exc}") from exc
        return Joints2D(self.layout, keypoints, int(frame.index), int(frame.timestamp_ns))

    def reset(self) -> None:
        """Forget the previous detections (BlazePose then crops the box's square, without a box the whole
        frame, next time)."""
        self.adapter.forget()

    def close(self) -> None:
        """Release the onnxruntime session; safe to call twice."""
        self.session = None
