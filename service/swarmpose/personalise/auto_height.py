"""Automatic height: a body whose shape the user did not give is scaled to the person's stature.

The default bodies are 1.75 m tall; people are not, and a body of the wrong height tracks them
worse. Personalisation (``--personalize N``) fits the whole shape but costs
tens of seconds; this is its cheap first step, on by default (``auto_height``).

**The measure** (:mod:`swarmpose.personalise.stature`, whose functions and constants this paragraph
and the next name: :func:`person_stature`). At a tracked frame where the person stands upright on
at least one leg, by the fitted pose (:func:`upright`) and by the lifted joints J^e
(:func:`lifted_upright`), the stature is the height of the top of the head above the floor, along
the floor's normal, where a floor is seen under the feet (:func:`floor_plane`), else above the
lowest points of the feet, along the fitted body's long axis (neck to mid-ankles); divided by
:data:`UPRIGHT_SHARE` (less :data:`HIDDEN_SOLE_SHARE` without a floor). The head is the person's
points above the fitted neck near the line along the axis through the fitted head, less those near
a fitted forearm and hand (a hand raised over the head is not its top); the feet are the points
below the fitted knees near the lines through the ankles. The fitted model only says where to look:
its size does not enter the measure. A hand on the head, or a head or feet cut off by the image's
border, give no measure.

The head above the floor is the observation's alone, rather than a comparison with the fitted
model's own render, because the tracker's fits absorb a wrong size (a body too tall sinks its feet
below the floor the depth cannot see there, bends, leans).

**The person's points** (:func:`person_mask`): the observed pixels inside the model's silhouette
grown by :data:`GROW_DOWN_UP` of its pixel height up and down and :data:`GROW_SIDEWAYS` sideways
(a taller person reaches beyond the model's head), within :data:`DEPTH_BAND_M` of the model's
median depth: a wall farther behind the person than that is left out. Only the window of the
model's projection grown by those margins is ray-cast and searched (:func:`_window`).

**The body** (:class:`HeightFitting`, a tracker's fitting): the median of the first :data:`FIRST_ESTIMATES`
upright frames' statures scales the body uniformly about its origin (:func:`scaled_body`; for
the built-in body exactly its stature parameter, for a MakeHuman body its size at unchanged
proportions); the median of the first :data:`ESTIMATES` scales it once more, and it is then
locked. The factor is clamped to :data:`FACTOR_LIMITS`. A person who never stands upright keeps
the given body; a new person starts from the given body again.

Limits: a person jumping (jumping jacks) is measured in the air as well; MakeHuman subjects
come out up to about 2 % short (the top of their heads against their stature differs from the
built-in body's, on which :data:`UPRIGHT_SHARE` is calibrated); a single-person tracker
(``--max-people 1``) cannot tell another person from a lost track, so the height stays the first
person's (:meth:`HeightFitting.new_person` starts again; several people's trackers call
it for every new id).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.personalise.stature import upright_stature
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker, observed_depth
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult

log = logging.getLogger(__name__)

FIRST_ESTIMATES = 3
"""Upright frames after which the body is scaled a first time (median of their factors) ..."""
ESTIMATES = 10
"""... and after which it is scaled by the median of all and kept: UTD-MHAD's clips are two
seconds long, so the body should change early, and real depth moves one frame's measure by a
few centimetres (the median of ten is steadier)."""
FACTOR_LIMITS = (0.8, 1.2)
"""The scale factor is clamped to this range (1.40-2.10 m from a 1.75 m body)."""


def applies(body_spec: str, shape: str, config: TrackerConfig) -> bool:
    """Whether a tracker of ``body_spec`` (``--body``) with ``shape`` (``--shape``) under ``config``
    measures the height: ``auto_height`` is on, the body is ``builtin`` or ``makehuman:DIR`` with no
    shape given (a .glb is someone's own body), nothing personalises it and the mode fits a body."""
    spec = body_spec.strip().lower()
    own = spec == "builtin" or spec.startswith("makehuman:")
    return bool(config.auto_height and own and not shape.strip() and config.personalize == 0
                and config.mode != "lift")


def scaled_body(body: SkinnedBody, factor: float) -> SkinnedBody:
    """``body`` scaled uniformly by ``factor`` about its origin (the pose's root): the rest
    vertices, bone pivots, named points and the bind matrices' translations. Skinning and
    triangles are unchanged, so a tracker takes it with :meth:`BodyTracker.set_body`."""
    binds = np.array(body.bind_matrices, dtype=np.float64, copy=True)
    binds[:, :3, 3] *= factor
    return replace(body, name=f"{body.name} x{factor:.3f}", vertices=np.asarray(body.vertices) * factor,
                   bone_heads=np.asarray(body.bone_heads) * factor,
                   bind_matrices=binds.astype(np.asarray(body.bind_matrices).dtype),
                   point_rest=np.asarray(body.point_rest) * factor,
                   metadata={**body.metadata, "height_scale": float(factor)})


class HeightFitting:
    """A tracker's :class:`~swarmpose.tracking.fitting.BodyFitting` that scales its body to the
    person's height on the first upright frames it tracks: at once after :data:`FIRST_ESTIMATES`
    of them, finally after :data:`ESTIMATES`, then keeps it (see the module docstring).

    ``factors``: each measured frame's stature over the given body's; ``factor``: the scale
    applied now (1 at first); ``locked`` after :data:`ESTIMATES`; ``given_body``: the tracker's
    body when attached; :meth:`personalisation` reports them as status and info do."""

    def __init__(self) -> None:
        self.given_body: SkinnedBody | None = None
        self.factors: list[float] = []
        self.factor = 1.0
        self.locked = False

    def attach(self, tracker: BodyTracker) -> None:
        """Remember the tracker's body (its tracking level of detail) as the one to scale."""
        self.given_body = tracker.body

    def new_person(self, tracker: BodyTracker) -> None:
        """Another person: the given body again, and a new measure."""
        if self.factor != 1.0:
            tracker.set_body(self.given_body)
        self.factors, self.factor, self.locked = [], 1.0, False

    def after_frame(self, tracker: BodyTracker, frame: Frame, joints: Joints2D | None, others_removed: bool,
                    result: BodyResult) -> None:
        """Measure the person's stature on this frame where it is upright; rescale after enough."""
        found = result.found
        if self.locked or found.state == "lost" or found.pose is None:
            return
        targets = tracker.objective.targets if tracker.objective is not None else None
        try:
            stature = (None if targets is None else
                       upright_stature(tracker.body, found.pose, observed_depth(frame.depth), tracker.intrinsics,
                                       targets.names, targets.xyz))
        except Exception as exc:  # a failed measure must not cost the frame its fit
            log.debug("frame %d: body %d: no height measure (%s: %s)", frame.index, tracker.body_id,
                      type(exc).__name__, exc)
            stature = None
        if stature is not None and np.isfinite(stature):
            self.factors.append(stature / self.given_body.height)
            if len(self.factors) in (FIRST_ESTIMATES, ESTIMATES):
                self._rescale(tracker)

    def _rescale(self, tracker: BodyTracker) -> None:
        """Scale the given body by the median factor so far (clamped); lock it after :data:`ESTIMATES`."""
        self.factor = float(np.clip(np.median(self.factors), *FACTOR_LIMITS))
        tracker.set_body(scaled_body(self.given_body, self.factor))
        self.locked = len(self.factors) >= ESTIMATES
        log.log(logging.INFO if self.locked else logging.DEBUG,
                "body %d: height %.3f m from the depth of %d upright frames (the body scaled by %.3f)%s",
                tracker.body_id, tracker.body.height, len(self.factors), self.factor,
                "" if self.locked else "; measuring on")

    def personalisation(self, tracker: BodyTracker) -> dict:
        """This body's state as the status and info messages' ``personalisation`` reports it:
        ``collecting`` its :data:`ESTIMATES` upright frames (``frames`` so far), then ``locked``;
        ``parameters``: the ``scale`` applied to the given body; ``height_m``: the body's now."""
        return {"id": tracker.body_id, "state": "locked" if self.locked else "collecting",
                "frames": min(len(self.factors), ESTIMATES), "needed": ESTIMATES,
                "parameters": {"scale": round(self.factor, 4)}, "height_m": round(tracker.body.height, 4)}


def height_fitting_tracker(body: SkinnedBody, intrinsics: Intrinsics, config: TrackerConfig | None = None,
                           context: ClContext | None = None, body_id: int = 0) -> BodyTracker:
    """A :class:`BodyTracker` of ``body`` whose :class:`HeightFitting` scales it to the person."""
    return BodyTracker(body, intrinsics, config, context, body_id, fitting=HeightFitting())
