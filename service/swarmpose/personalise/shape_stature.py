"""The stature term of the shape fit (:func:`swarmpose.personalise.personalise.fit_shape`): the
person's height measured on the depth bounds the fitted body's.

**Why.** The fit's own objective barely tells heights apart (across a few cm its energy moves
by about as much as a pose refit's scatter), so some builds come out centimetres off with errors
of one sign. The automatic height's measure (:func:`swarmpose.personalise.stature.person_stature`:
the top of the head above the floor, where the fitted pose only says where to look) reads a walk
slightly short, hence the lopsided band below.

**The term.** At every sample where the lifted joints stand upright on a straight knee
(:func:`~swarmpose.personalise.stature.upright_stature` without the fitted pose's test: the samples
were tracked with the start body, whose poses bend where it is too tall), the stature is
measured; their median
``H`` needs :data:`MIN_MEASURES` of them. A body whose rest height lies in :data:`BAND` around
``H`` costs nothing; beyond it, :data:`WEIGHT` per cm. The band is lopsided because posture only
lowers the head: a person's head top is never above their stature but for the measure's noise
(:data:`BAND`'s lower share), while a walk lowers it by up to about 1.2 %.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.personalise.fit_settings import STATURE_WEIGHT
from swarmpose.personalise.stature import upright_stature
from swarmpose.tracking.body_tracker import observed_depth
from swarmpose.tracking.objective import JointTargets

log = logging.getLogger(__name__)
MIN_MEASURES = 3
"""Fewest upright samples with a measure for the term to apply (fewer: no term)."""
BAND = (-0.003, 0.015)
"""Rest heights from ``H·(1 + BAND[0])`` to ``H·(1 + BAND[1])`` cost nothing (``H``: the measured
stature; see the module docstring)."""
WEIGHT = STATURE_WEIGHT
"""Energy per cm that a body's rest height lies outside the band (declared in :mod:`~.fit_settings`)."""


def measured_stature(samples: Sequence, body: SkinnedBody, intrinsics: Intrinsics, min_score: float
                     ) -> tuple[float | None, int]:
    """(the median stature (m) measured at the ``samples`` (each with ``frame``, ``joints`` and
    the ``pose`` (36,) tracked with ``body``) where the lifted joints stand upright on a straight
    knee, how many were measured); the median is None with fewer than :data:`MIN_MEASURES`."""
    measures = []
    for sample in samples:
        try:
            depth = observed_depth(sample.frame.depth)
            targets = JointTargets.from_detection(sample.joints, depth, intrinsics, body, min_score)
            stature = upright_stature(body, sample.pose, depth, intrinsics, targets.names, targets.xyz, by_fit=False)
        except Exception as exc:  # one frame's failed measure must not cost the fit
            log.debug("frame %d: no stature measure (%s: %s)", sample.frame.index, type(exc).__name__, exc)
            continue
        if stature is not None and np.isfinite(stature):
            measures.append(stature)
    if len(measures) < MIN_MEASURES:
        return None, len(measures)
    return float(np.median(measures)), len(measures)


def full_height(body: SkinnedBody) -> float:
    """The rest height (m) of the full body that ``body`` (a shape space's fitting body) stands for:
    its metadata's ``full_height_m`` where the space gives it, else its own."""
    return float(body.metadata.get("full_height_m", body.height))


def stature_energy(height_m: float, measured_m: float | None, weight: float = WEIGHT) -> float:
    """``weight`` per cm that ``height_m`` (a body's rest height, m) lies outside :data:`BAND`
    around ``measured_m`` (m); 0 without a (finite) measure."""
    if measured_m is None or not np.isfinite(measured_m) or weight <= 0:
        return 0.0
    low, high = measured_m * (1 + BAND[0]), measured_m * (1 + BAND[1])
    return weight * 100.0 * max(low - height_m, height_m - high, 0.0)
