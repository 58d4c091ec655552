"""The public Python API: :class:`Tracker` for frames from your own code, :func:`track` for
any source URI. Both run the same per-frame step as the command line.

    import swarmpose
    K = swarmpose.Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    with swarmpose.Tracker(body="builtin", detector="onnx:movenet.onnx", intrinsics=K) as tracker:
        result = tracker.track(depth_m, rgb, timestamp_ns=t_ns)
        for body in result.bodies:
            print(body.id, body.state, body.joints["left_wrist"].position_m)
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

import numpy as np

from swarmpose.body.loader import load_body
from swarmpose.body.shape_space import shape_space_for
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ShapeError
from swarmpose.core.settings import with_settings
from swarmpose.detect.joints import Detector
from swarmpose.detect.registry import detector_note, make_detector
from swarmpose.pipeline.builder import build_pipeline
from swarmpose.pipeline.features import refuse
from swarmpose.pipeline.run import results, source_error
from swarmpose.sources.base import Frame, FrameSource, SkippedFrame
from swarmpose.sources.registry import open_source
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import FrameResult

log = logging.getLogger(__name__)


class Tracker:
    """Tracks the people in a stream of RGBD frames.

    body: ``"builtin"``, ``"makehuman:DIR"``, a ``.glb``/``.gltf`` path, or a loaded
    :class:`~swarmpose.body.skinned.SkinnedBody`; shape: the body's shape preset or
    measurements (spec strings only). A ``"builtin"`` or ``"makehuman:DIR"`` body without a
    shape is scaled to each person's height on their first upright frames (``auto_height``,
    :mod:`swarmpose.personalise.auto_height`; a loaded body is kept as it is). detector: a spec
    (``"auto"``: the recorded detections of a ``source`` that has them, else ``"movenet"``;
    ``"movenet"``/``"blazepose"`` from the models folders, whatever the working directory
    (``models``, else ``$SWARMPOSE_MODELS``, first; see ``swarmpose models``); ``"onnx:MODEL.onnx"``,
    ``"openpose-json:DIR"``, ``"simulated"``) or an object with ``detect(frame, box)``;
    a detector made from a spec is the tracker's and closed with it. intrinsics: the
    camera (needed by :meth:`track`; :meth:`track_frame` takes each frame's own). source:
    the frame source, needed by the ``simulated`` detector (it replays the recorded
    detections of a ``swarmpose synth`` sequence). config: a
    :class:`~swarmpose.tracking.config.TrackerConfig`; settings: any of its fields by name
    (``particles=32``, ``mode="joints"``, ``tile="32x48"``), over ``config``, converted and
    checked as flags are (ConfigError for a wrong type, NaN or a value out of range);
    ``personalize=N`` fits each person's body on their first N tracked frames (a body given by
    name). coordinates: ``"camera"`` or ``"world"`` (the results' messages floor-aligned: y up,
    the floor at y = 0, the origin under the first tracked person); floor: ``"auto"`` (fitted to
    the depth), ``"off"`` or an extrinsics JSON file (default: ``"auto"`` for world coordinates,
    else ``"off"``). The pipeline is the command line's (:mod:`swarmpose.pipeline.builder`).

    The tracker feeds each frame's tracked joints back to the detector (where to look next)
    and restarts a track that fails. Use it as a context manager, or call :meth:`close`.
    """

    def __init__(self, body: str | SkinnedBody = "builtin", detector: str | Detector = "auto",
                 intrinsics: Intrinsics | None = None, *, shape: str | None = None,
                 source: FrameSource | None = None, config: TrackerConfig | None = None, coordinates: str = "camera",
                 floor: str | None = None, models: str = "", **settings: Any):
        self.config = with_settings(config or TrackerConfig(), **settings)
        if isinstance(detector, str) and detector.strip() == "simulated" and source is None:
            raise ConfigError("the simulated detector draws its keypoints from a source's ground truth (a "
                              "`swarmpose synth` sequence or a UTD-MHAD file), so it needs that source: pass "
                              "source=swarmpose.open_source('folder:SEQ'), or a "
                              "detector for other frames, e.g. detector='onnx:movenet.onnx' or "
                              "detector='openpose-json:DIR'")
        if isinstance(body, SkinnedBody):
            if shape:
                raise ConfigError("shape applies to a body spec string; a loaded body already has its shape")
            loaded = body
        else:
            loaded = load_body(body, shape or None)
        space = None
        if self.config.personalize:  # fitted online from the start body of its shape space
            if not isinstance(body, str):
                raise ConfigError("personalize fits a body's shape space: give the body by name (builtin or "
                                  "makehuman:DIR), not as a loaded body")
            space = shape_space_for(body, shape or "", self.config.triangles)
            loaded = space.tracking_body(space.start)
        triangles = self.config.triangles
        self.body = loaded if len(loaded.triangles) <= triangles else loaded.tracking_lod(triangles)
        self._owns_detector = isinstance(detector, str)
        self.detector: Detector = (make_detector(detector, source, models) if isinstance(detector, str)
                                   else detector)
        log.info("%s", detector_note(detector if isinstance(detector, str) else "", self.detector))
        self.intrinsics = intrinsics
        self.pipeline = build_pipeline("offline", self.body, self.detector, self.config,
                                       body_spec=body if isinstance(body, str) else "", shape=shape or "",
                                       space=space, floor=floor or ("auto" if coordinates == "world" else "off"),
                                       coordinates=coordinates)
        self._next_index = 0
        self._closed = False

    def track(self, depth_m: np.ndarray, rgb: np.ndarray | None = None, timestamp_ns: int = 0,
              index: int | None = None) -> FrameResult:
        """Track one frame. depth_m: (H, W) float metres, 0 (or NaN) = no measurement; rgb: (H, W, 3)
        uint8 RGB registered to the depth, or None (a detector that needs colour then finds
        nobody); timestamp_ns: capture time; index: frame number (default: counts from 0)."""
        if self.intrinsics is None:
            raise ConfigError("Tracker.track needs the camera: pass intrinsics=swarmpose.Intrinsics(width, height, "
                              "fx, fy, cx, cy) to Tracker, or call track_frame with frames that carry theirs")
        depth = np.asarray(depth_m, dtype=np.float32)
        size = (self.intrinsics.height, self.intrinsics.width)
        if depth.shape != size:
            raise ShapeError(f"depth_m has shape {depth.shape}, expected {size} (the intrinsics' height, width)")
        if rgb is not None:
            rgb = np.asarray(rgb)
            if rgb.shape != (*size, 3) or rgb.dtype != np.uint8:
                raise ShapeError(f"rgb has shape {rgb.shape} and dtype {rgb.dtype}, expected {(*size, 3)} uint8 "
                                 "(RGB registered to the depth)")
        i = self._next_index if index is None else int(index)
        return self.track_frame(Frame(i, int(timestamp_ns), depth, rgb, self.intrinsics))

    def track_frame(self, frame: Frame | SkippedFrame) -> FrameResult:
        """Track one frame of a source (a skipped frame gives a result that says why)."""
        if self._closed:
            raise ConfigError("this Tracker is closed; make a new one")
        refuse("frame_by_frame", self.config)
        self._next_index = frame.index + 1
        return self.pipeline.process(frame)

    def reset(self) -> None:
        """Forget the tracks and the heights measured for their people: the next frame starts
        from its detections."""
        self.pipeline.reset()

    def close(self) -> None:
        """Release the detector (when the tracker made it)."""
        if not self._closed and self._owns_detector:
            self.detector.close()
        self._closed = True

    def __enter__(self) -> Tracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def track(source: str | FrameSource, *, body: str | SkinnedBody = "builtin", detector: str | Detector = "auto",
          shape: str | None = None, frames: int = 0, **settings: Any) -> Iterator[FrameResult]:
    """Track every frame of ``source`` (a URI such as ``"folder:DIR"``, ``"mkv:FILE"``,
    ``"realsense:"``, or an open source), yielding a :class:`FrameResult` per frame; at most
    ``frames`` (0 = all). Other arguments as for :class:`Tracker`. The source (when opened
    here) and the detector are closed when the iteration ends or is abandoned. A source that
    ends by failing (``status`` ``"error: …"``, e.g. a truncated recording) ends the iteration
    after its last good frame with a warning on the ``swarmpose`` logger."""
    opened = open_source(source) if isinstance(source, str) else source
    try:
        with Tracker(body, detector, shape=shape, source=opened, **settings) as tracker:
            yield from results(opened, tracker.pipeline, frames)
            source_error(opened)
    finally:
        if isinstance(source, str):
            opened.close()
