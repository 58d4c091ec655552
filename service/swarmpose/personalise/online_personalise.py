"""``--personalize N``: a tracker that personalises its body from its own first N tracked frames.

:func:`personalising_tracker` tracks with the shape space's start body, keeps the first N frames
it tracked (depth and detection; colour is dropped), then fits the shape on them
(:func:`~swarmpose.personalise.personalise.fit_shape` with its default settings, the last stage of
own poses included, in the tracking thread: that frame takes the fit's seconds), takes the new body
and locks it for the rest of the run. Each person of a
several-people run has a tracker of their own, so each is personalised on their own frames, and
only on frames where no one else hides them (:data:`MAX_HIDDEN_SHARE`): a person partly behind
another was fitted to what was left of them (the 3-person crossing's waver, 2 m behind two
walkers, came out a slim, mostly female body instead of the heavy male he is).
A fit that fails (too few frames tracked) leaves the start body and says why.
"""

from __future__ import annotations

import logging
from dataclasses import replace

from swarmpose.body.shape_space import ShapeSpace
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SwarmposeError
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.personalise.personalise import FitSettings, ShapeSample, body_measures, fit_shape
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult

log = logging.getLogger(__name__)

MAX_HIDDEN_SHARE = 0.2
"""With other people in view, a frame is collected only while at most this share of the model's
rendered pixels lacks an observation: a person partly behind another (whose depth was removed)
would be fitted to what is left of them."""


class OnlinePersonalisation:
    """A tracker's :class:`~swarmpose.tracking.fitting.BodyFitting` that fits its body to the person
    after ``needed`` tracked frames, in the shape space ``space`` (the tracker starts with
    ``space``'s start body: :func:`personalising_tracker`).

    :meth:`personalisation` reports ``state`` (``collecting``, ``locked`` or ``failed``),
    ``frames`` collected, ``needed``, and once locked the ``parameters``, ``height_m`` and
    ``volume_l`` of the fitted body (``reason`` when it failed)."""

    def __init__(self, space: ShapeSpace, needed: int, settings: FitSettings):
        self.space, self.needed, self.settings = space, int(needed), settings
        self.start_body = space.tracking_body(space.start)
        self.samples: list[ShapeSample] = []
        self.state, self.reason = "collecting", ""
        self.found: dict = {}

    def attach(self, tracker: BodyTracker) -> None:
        """Nothing to remember: the start body is the space's."""

    def new_person(self, tracker: BodyTracker) -> None:
        """Another person: the start body again, and a new personalisation."""
        if self.state != "collecting":  # a collecting tracker still has the start body
            tracker.set_body(self.start_body)
        self.samples, self.state, self.reason, self.found = [], "collecting", "", {}

    def after_frame(self, tracker: BodyTracker, frame: Frame, joints: Joints2D | None, others_removed: bool,
                    result: BodyResult) -> None:
        """Collect this frame while collecting (not where others hide much of the person); fit
        the body once ``needed`` are collected."""
        found = result.found
        if (self.state == "collecting" and found.state != "lost" and found.pose is not None
                and not (others_removed and tracker.weights.depth > 0 and hidden_share(tracker) > MAX_HIDDEN_SHARE)):
            self.samples.append(ShapeSample(replace(frame, color=None), joints, found.pose))
            if len(self.samples) >= self.needed:
                self.personalise(tracker)

    def personalise(self, tracker: BodyTracker) -> None:
        """Fit the body on the samples collected (a failure leaves the start body and says why)."""
        log.info("body %d: personalising from %d frames", tracker.body_id, len(self.samples))
        context = tracker.objective.scorer.cl_context if tracker.objective is not None else None
        try:
            fit = fit_shape(self.space, self.samples, tracker.intrinsics, tracker.config, self.settings,
                            context=context)
            found = {"parameters": fit.parameters, "shape": self.space.shape_spec(fit.x), **body_measures(fit.body)}
            tracker.set_body(fit.tracking_body)
        except Exception as exc:  # a fit that fails leaves the start body, says why and is not tried again
            self.reason = str(exc) if isinstance(exc, SwarmposeError) else f"{type(exc).__name__}: {exc}"
            self.state = "failed"
            log.warning("body %d: personalisation failed: %s", tracker.body_id, self.reason)
        else:
            self.found = found
            self.state = "locked"
            log.info("body %d: shape locked after %.1f s: %s (height %.3f m; stature measured on the depth: %s)",
                     tracker.body_id, fit.seconds, self.found["shape"], self.found["height_m"],
                     "none" if fit.stature_m is None else f"{fit.stature_m:.3f} m")
        finally:
            self.samples = []

    def personalisation(self, tracker: BodyTracker) -> dict:
        """The state of the personalisation (see the class docstring)."""
        out = {"id": tracker.body_id, "state": self.state, "frames": self.needed if self.state != "collecting"
               else len(self.samples), "needed": self.needed}
        if self.state == "locked":
            out.update({k: self.found[k] for k in ("parameters", "height_m", "volume_l")})
        if self.reason:
            out["reason"] = self.reason
        return out


def hidden_share(tracker: BodyTracker) -> float:
    """The share of the model's rendered pixels at ``tracker``'s last solution that have no
    observed depth in that frame (from the counts the step's verdict used); 1 where its box
    held no depth. Asked only of a tracker that scores depth (not ``--mode joints``)."""
    counts = tracker.best_counts
    if counts is None or not int(counts["rendered"][0]):
        return 1.0
    return 1.0 - int(counts["both"][0]) / int(counts["rendered"][0])


def personalising_tracker(space: ShapeSpace, needed: int, intrinsics: Intrinsics, config: TrackerConfig | None = None,
                          context: ClContext | None = None, body_id: int = 0,
                          settings: FitSettings | None = None) -> BodyTracker:
    """A :class:`BodyTracker` of ``space``'s start body whose :class:`OnlinePersonalisation` fits it to
    the person after ``needed`` tracked frames."""
    config = config or TrackerConfig()
    fitting = OnlinePersonalisation(space, needed, settings or FitSettings(seed=config.seed))
    return BodyTracker(fitting.start_body, intrinsics, config, context, body_id, fitting=fitting)
