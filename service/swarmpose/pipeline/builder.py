"""The one builder of the per-frame pipeline: every driver (the offline run, the threaded worker,
the Python API, personalise) asks :func:`build_pipeline` for its :class:`FramePipeline` (or an
ensemble of them), so a feature is wired in one place and refused in one place
(:mod:`swarmpose.pipeline.features`).

Which tracker each person gets (:func:`body_fitting`): with a shape space and ``personalize`` N,
one that fits the person's body on their first N tracked frames; where the automatic height
applies, one that scales the body to the person's stature; else the body as it is.

The backward pass (:mod:`swarmpose.pipeline.backward`) and the shape fit
(:mod:`swarmpose.personalise.personalise`) take no pipeline from here: they refit one person's
recorded steps (no detection, no people) with a single-body tracker of that step's body and settings.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from swarmpose.body.shape_space import ShapeSpace
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.detect.joints import Detector
from swarmpose.personalise.auto_height import ESTIMATES as HEIGHT_ESTIMATES
from swarmpose.personalise.auto_height import applies, height_fitting_tracker
from swarmpose.personalise.online_personalise import personalising_tracker
from swarmpose.pipeline.features import refuse
from swarmpose.pipeline.step import FramePipeline
from swarmpose.pipeline.world import make_world
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

if TYPE_CHECKING:
    from swarmpose.pipeline.ensemble import EnsemblePipeline

TrackerFactory = Callable[[TrackerConfig, Intrinsics, int], BodyTracker]
"""(settings, camera, body id) -> the tracker of one person."""


def body_fitting(body: SkinnedBody, tracker: TrackerConfig, body_spec: str, shape: str,
                 space: ShapeSpace | None) -> tuple[TrackerFactory, int]:
    """(the factory of each person's tracker, the frames its body fitting needs: 0 for none).

    body_spec, shape: the ``--body`` and ``--shape`` the body came from ("" for a body given as
    an object: it is kept as it is); space: the shape space ``personalize`` fits in."""
    if tracker.personalize > 0:
        if space is None:
            raise ConfigError(f"personalize = {tracker.personalize} needs a body with a shape space (builtin or "
                              "makehuman:DIR, given by name)")

        def personalising(settings: TrackerConfig, intrinsics: Intrinsics, body_id: int) -> BodyTracker:
            return personalising_tracker(space, tracker.personalize, intrinsics, settings, body_id=body_id)
        return personalising, tracker.personalize
    if body_spec and applies(body_spec, shape, tracker):
        def height_fitting(settings: TrackerConfig, intrinsics: Intrinsics, body_id: int) -> BodyTracker:
            return height_fitting_tracker(body, intrinsics, settings, body_id=body_id)
        return height_fitting, HEIGHT_ESTIMATES

    def plain(settings: TrackerConfig, intrinsics: Intrinsics, body_id: int) -> BodyTracker:
        return BodyTracker(body, intrinsics, settings, body_id=body_id)
    return plain, 0


def build_pipeline(driver: str, body: SkinnedBody, detector: Detector, tracker: TrackerConfig, *,
                   body_spec: str = "", shape: str = "", space: ShapeSpace | None = None, floor: str = "off",
                   coordinates: str = "camera", one_person: bool = False) -> FramePipeline | EnsemblePipeline:
    """The per-frame step of ``driver`` (:data:`swarmpose.pipeline.features.DRIVERS`) tracking ``body``
    (already at its tracking level of detail) with ``detector`` under ``tracker``.

    body_spec, shape, space: see :func:`body_fitting`; floor, coordinates: the world frame
    (:func:`~swarmpose.pipeline.world.make_world`; floor ``"off"``: none); one_person: one person on
    the whole frame whatever ``max_people`` says (personalise). With ``ensemble`` N > 1, N pipelines
    with seeds seed .. seed + N - 1, averaged (:mod:`swarmpose.pipeline.ensemble`); only the first
    publishes the world frame. ConfigError for a feature ``driver`` cannot run."""
    refuse(driver, tracker)
    tracker_of, fitting_frames = body_fitting(body, tracker, body_spec, shape, space)

    def member(seed: int) -> FramePipeline:
        settings = replace(tracker, seed=seed)
        return FramePipeline(detector, lambda intrinsics, body_id: tracker_of(settings, intrinsics, body_id),
                             1 if one_person else tracker.max_people, tracker.retire_frames,
                             personalise_frames=fitting_frames,
                             world=make_world(floor, coordinates) if seed == tracker.seed else None,
                             backward=tracker.backward, centred_sigma_s=tracker.centred_sigma_s,
                             box_hold=tracker.box_hold)
    if tracker.ensemble <= 1:
        return member(tracker.seed)
    from swarmpose.pipeline.ensemble import ensemble_of  # its imports (scipy.optimize) only for an ensemble

    return ensemble_of(member, tracker.seed, tracker.ensemble)
