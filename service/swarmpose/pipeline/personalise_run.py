"""``swarmpose personalize``'s run: track the first frames of a source with the shape space's
start body (one person), then fit the shape (:func:`swarmpose.personalise.personalise.fit_shape`)."""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, replace

from swarmpose.body.shape_space import ShapeSpace, shape_space_for
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import PersonalisationError
from swarmpose.core.progress import progress_bar
from swarmpose.detect.registry import make_detector
from swarmpose.personalise.personalise import FitSettings, ShapeFit, ShapeSample, fit_shape
from swarmpose.pipeline.builder import build_pipeline
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.run import remember_frames, results
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source

log = logging.getLogger(__name__)


@dataclass
class Personalised:
    """A fit and what it came from: the space, the samples (frames tracked with a pose) and
    the frames read."""

    fit: ShapeFit
    space: ShapeSpace
    samples: list[ShapeSample]
    frames_read: int


def collect_samples(config: ServiceConfig, space: ShapeSpace, frames: int,
                    show_progress: bool = True) -> tuple[list[ShapeSample], Intrinsics | None, int]:
    """Track the first ``frames`` frames of ``config.source`` (one person) with the start body
    of ``space``: (the samples with a pose, the camera, the frames read). The tracker's offline
    settings apply to the samples' poses: the backward pass, the centred smoothing and the ensemble."""
    config.require_source()
    tracker_config = replace(config.tracker, triangles=space.triangles)  # the pipeline tracks one person
    body = space.tracking_body(space.start)
    samples: list[ShapeSample] = []
    intrinsics = None
    read = 0
    with ExitStack() as stack:
        source = open_source(config.source)
        stack.callback(source.close)
        detector = make_detector(config.detector, source, config.models)
        stack.callback(detector.close)
        # one person with the space's start body as it is (the fit measures the shape itself)
        pipeline = build_pipeline("offline", body, detector, replace(tracker_config, personalize=0),
                                  one_person=True)
        frames_of: dict[int, Frame] = {}
        with progress_bar("personalise: track", frames or getattr(source, "length", None),
                          enabled=show_progress) as bar:
            for result in results(remember_frames(source, frames_of), pipeline, frames):
                read += 1
                bar.update(1)
                frame = frames_of.pop(result.index, None)
                if frame is None or not result.bodies:
                    continue
                tracked = result.bodies[0]
                intrinsics = frame.intrinsics
                if tracked.state != "lost" and tracked.pose is not None:
                    samples.append(ShapeSample(replace(frame, color=None), tracked.detection, tracked.pose))
    return samples, intrinsics, read


def personalise(config: ServiceConfig, frames: int, settings: FitSettings | None = None,
                show_progress: bool = True) -> Personalised:
    """The shape of the person in the first ``frames`` frames of ``config.source``, in the
    shape space of ``config.body`` (``makehuman:DIR`` or ``builtin``)."""
    space = shape_space_for(config.body, config.shape, config.tracker.triangles)
    samples, intrinsics, read = collect_samples(config, space, frames, show_progress)
    if intrinsics is None or not samples:
        raise PersonalisationError(f"{config.source}: no person was tracked in {read} frames; check that a person "
                                   "is in view and the detector (--detector) suits the source")
    fit = fit_shape(space, samples, intrinsics, config.tracker, settings or FitSettings(),
                    progress=(lambda line: log.info("personalise: %s", line)) if show_progress else None)
    return Personalised(fit, space, samples, read)
