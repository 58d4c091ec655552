"""A track's start and its re-checks: the J^e torso pose turned to each facing, fitted.

A side or back view makes the facing of the lifted torso unreliable, so a track starts from four
facings (:func:`fit_facings`), and the facings are refitted and compete with the track on a young
track's first frames and every ``recheck`` frames after (:func:`recheck_facings`).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from swarmpose.tracking import search
from swarmpose.tracking.budget import start_budget
from swarmpose.tracking.config import MODE_WEIGHTS
from swarmpose.tracking.init_pose import FACINGS_DEG, torso_pose, turned
from swarmpose.tracking.objective import JointTargets, Objective

if TYPE_CHECKING:
    from swarmpose.tracking.body_tracker import BodyTracker

YOUNG_RECHECKS = (1, 2, 4)
"""Track ages (frames after the start) at which the start's facings are refitted too, besides
every ``config.recheck`` frames: the start's pick rests on one frame's detection, and a
detector that swapped sides on that frame (people seen from behind) locked the track in the
mirrored facing until the next re-check."""


def recheck_due(index: int, age: int, every: int) -> bool:
    """Whether frame ``index`` of a track ``age`` frames old (1 = the first after its start)
    re-checks the facings: every ``every`` frames and at :data:`YOUNG_RECHECKS` (0: never)."""
    return bool(every) and (index % every == 0 or age in YOUNG_RECHECKS)


def fit_facings(tracker: BodyTracker, centre: np.ndarray, targets: JointTargets, depth: np.ndarray,
                rng: np.random.Generator, timings: dict[str, float],
                generations: int | None = None) -> list[np.ndarray]:
    """Start poses for ``tracker``'s frame without a track, best first.

    A side or back view makes the facing of the lifted torso unreliable (the far shoulder
    and hip lift onto the near side), so the start tries the J^e torso pose turned to each
    of :data:`FACINGS_DEG`. From each, two PSOs over wide angle ranges: first of the joint
    term alone (no rendering; the limbs find their detections), then of the full objective
    (with the joint term on also in depth mode) from there. The fits are ranked by that
    objective, so depth and the face's keypoints decide between a facing and its mirror. (One
    PSO of the full objective from the rest angles leaves a side view's limbs unfitted: the depth
    term is nearly flat in them and dominates E.) ``generations``: a re-check's (None: a start).
    A live re-check (the tracker has a frame budget) runs the joint stage alone: its fits are still
    ranked by the full objective and join the frame's swarm, which scores them on the depth anyway,
    and the full stage's rendering doubled the cost of a frame that re-checks (the latency's tail).
    """
    if targets.count == 0:
        return [centre]
    t = time.perf_counter()
    w_d, w_j = MODE_WEIGHTS["hybrid"]  # depth mode: the joints weigh as much as in hybrid
    weights = replace(tracker.weights, joints=max(tracker.weights.joints, tracker.weights.depth * w_j / w_d))
    box = tracker.search_box(centre, targets)
    joint_objective = None
    if weights.depth > 0 and bool(np.any(depth > 0)):
        joint_objective = Objective(tracker.body, tracker.intrinsics, tracker.objective.scorer,
                                    replace(weights, depth=0.0, joints=1.0))
        joint_objective.set_targets(targets)
    start_objective = (tracker.objective if weights == tracker.weights
                       else Objective(tracker.body, tracker.intrinsics, tracker.objective.scorer, weights,
                                      tracker.objective.coarse))
    start_objective.set_frame(depth, box, targets, centre)
    # a start runs once per track, so it gets at least config.start_budget (a smaller one left a side
    # view's start unconverged), live a share of it; a re-check the frame's generations, live the start's particles
    first = generations is None
    full_stage = first or tracker.budget_ms <= 0  # live, a re-check fits the joints alone (see the doc)
    config = tracker.config
    particles, budget = start_budget(config.start_budget, tracker.budget_ms, config.particles, config.generations)
    if not first:
        particles, budget = (particles if tracker.budget_ms > 0 else config.particles), generations
    # joints only (no depth): the joint stage is the whole fit, at twice the generations
    pso = replace(config.pso_config, variant="perturbed",
                  generations=budget * (1 if joint_objective is not None else 2), particles=particles)
    fits = []
    for degrees in FACINGS_DEG:
        facing = turned(tracker.body, centre, degrees)
        start = search.spread(facing, pso.particles, rng, np.full(3, 0.08), 0.3, 1.0)
        start[0] = facing
        fit = tracker.pso_search(joint_objective or start_objective, start, rng, pso).best
        if joint_objective is not None and full_stage:
            start = search.spread(fit, pso.particles, rng, np.full(3, 0.04), 0.1, 0.3)
            start[0] = fit
            fit = tracker.pso_search(start_objective, start, rng, pso).best
        fits.append(fit)
    energy = start_objective(np.stack(fits))
    timings["init" if first else "recheck"] = 1000 * (time.perf_counter() - t)
    return [fits[k] for k in np.argsort(energy)]


def recheck_facings(tracker: BodyTracker, index: int, lifted: dict[str, np.ndarray], targets: JointTargets,
                    depth: np.ndarray, rng: np.random.Generator, timings: dict[str, float],
                    generations: int) -> list[np.ndarray]:
    """Every ``config.recheck`` frames and on a young track's :data:`YOUNG_RECHECKS` frames,
    the start's facings refitted from the detection on a quarter of ``generations`` (the tracker
    passes the frame's live, at least the start's offline; live the joint stage alone, :func:`fit_facings`):
    they join the swarm as particles, so a track locked in a wrong facing or limb configuration is
    replaced as soon as they explain the frame better."""
    if not recheck_due(index, tracker.age + 1, tracker.config.recheck) or targets.count == 0:  # this frame's age
        return []
    centre = torso_pose(tracker.body, lifted, tracker.body.rest_angles)
    if centre is None:
        return []
    return fit_facings(tracker, centre, targets, depth, rng, timings, max(generations // 4, 1))[:2]
