"""A frame's search sized to a time budget: the live service's frames must keep up with the camera.

Offline every frame gets the configured budget (``generations`` of the swarm, ``polish`` rounds).
Live (``serve``), a frame that takes longer than the camera's frames makes the worker drop the ones
that came meanwhile, and the next frame is further away. With a budget of B ms per frame, each
frame's swarm runs as many generations, and the polish as many rounds, as the time that the rest of
the frame leaves allows, up to the configured ones: 3/4 of it to the swarm and 1/4 to the polish
(the configured budgets' share). The cost of a scored pose and the time outside the search are
running means over the frames tracked so far (:class:`FrameBudget`). A starved search skips the
proposals (:func:`lean_frame`), and a track's start is smaller (:func:`start_budget`,
:meth:`FrameBudget.sized`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from swarmpose.tracking.pso import PsoConfig

SEARCH_SHARE = 0.75
"""The swarm's share of the time left for the search (the rest: the polish)."""
MIN_GENERATIONS = 6
"""A frame's swarm runs at least this many generations, whatever the budget."""
POLISH_CANDIDATES = 32
"""Poses one polish round scores (:func:`swarmpose.tracking.pose_polish.polish_pose`)."""
SMOOTHING = 0.3
"""The new frame's weight in the running means."""
LEAN_BELOW = 16
"""With a budget, a frame whose swarm gets fewer generations than this skips the limb flips and arm
proposals (and their sub-swarms): their host work (about 60 ms a frame on 2 cores) then costs the
search more than they give, and a sub-swarm needs generations to refine its hypothesis."""
LIVE_START_GENERATIONS = 16
"""With a budget, a track's start runs its swarm for at most this many generations after the facings' fits."""
LIVE_START_POLISH = 8
"""With a budget, a track's start polishes for at most this many rounds."""
AUTO_PERIOD_SHARE = 0.9
"""With the frame budget on auto, a live frame's tracking may take this share of the camera's frame period (30
ms at 30 frames/s): the tracker then takes nearly every frame, and a client's pose is fresher than with a longer
search of every other frame, as accurate."""
START_SHARE = 0.5
"""With a budget, a track's start runs this share of ``start_budget`` particles and generations each
(a quarter of the scored poses): a lost track's restart holds up every frame behind it."""


@dataclass
class FrameBudget:
    """The running cost model of one tracker: ms per scored pose, ms per frame outside the search."""

    ms_per_pose: float | None = None
    other_ms: float | None = None

    def plan(self, budget_ms: float, particles: int, generations: int, polish: int) -> tuple[int, int]:
        """(generations, polish rounds) that fit ``budget_ms``, never more than configured and at least
        :data:`MIN_GENERATIONS` generations where that many are configured (0: the configured ones; the
        configured ones also before the first frame is measured)."""
        if budget_ms <= 0 or self.ms_per_pose is None or self.other_ms is None:
            return generations, polish
        left = max(budget_ms - self.other_ms, 0.0)
        search = SEARCH_SHARE * left if polish else left
        fitted_g = int(search / (particles * self.ms_per_pose)) - 1  # generation 0 scores the start
        fitted_p = int((left - search) / (POLISH_CANDIDATES * self.ms_per_pose))
        return min(max(fitted_g, MIN_GENERATIONS), generations), max(min(fitted_p, polish), 0)

    def sized(self, budget_ms: float, pso: PsoConfig, polish: int, start: bool = False) -> tuple[PsoConfig, int]:
        """``pso`` with the generations and the polish rounds of a frame: those of :meth:`plan`; at a
        track's ``start`` (after its facings' fits, :func:`start_budget` each) the configured ones, with a
        budget at most :data:`LIVE_START_GENERATIONS` and :data:`LIVE_START_POLISH`, since every frame
        behind a live start waits for it."""
        if start:
            if budget_ms <= 0:
                return pso, polish
            generations, rounds = min(pso.generations, LIVE_START_GENERATIONS), min(polish, LIVE_START_POLISH)
        else:
            generations, rounds = self.plan(budget_ms, pso.particles, pso.generations, polish)
        return replace(pso, generations=generations), rounds

    def record(self, search_ms: float, poses: int, total_ms: float) -> None:
        """Fold in one frame: ``search_ms`` for ``poses`` scored poses (swarm and polish), ``total_ms`` in all."""
        if poses <= 0:
            return
        cost, other = search_ms / poses, max(total_ms - search_ms, 0.0)
        self.ms_per_pose, self.other_ms = running_mean(self.ms_per_pose, cost), running_mean(self.other_ms, other)


def running_mean(old: float | None, new: float, weight: float = SMOOTHING) -> float:
    """``new`` folded into the running mean ``old`` with ``weight`` (``new`` itself when there is none)."""
    return new if old is None else old + weight * (new - old)


def live_budget_ms(configured: float | None, frame_period_s: float) -> float:
    """A live frame's budget (ms): ``configured`` (``frame_budget_ms``; 0: the full search), or on auto (None)
    :data:`AUTO_PERIOD_SHARE` of ``frame_period_s``, the time between the frames that come (s)."""
    return AUTO_PERIOD_SHARE * 1000.0 * frame_period_s if configured is None else float(configured)


def lean_frame(budget_ms: float, generations: int) -> bool:
    """Whether a frame with ``generations`` planned under ``budget_ms`` (0: none) skips the proposals."""
    return budget_ms > 0 and generations < LEAN_BELOW


def start_budget(configured: int, budget_ms: float, particles: int, generations: int) -> tuple[int, int]:
    """(particles, generations) of each of a track's start PSOs: offline at least ``configured``
    (``start_budget``) and at least the frame's ``particles`` and ``generations``; with a budget
    :data:`START_SHARE` of ``configured`` each, whatever the frame's search runs."""
    if budget_ms > 0:
        least = max(int(configured * START_SHARE), 1)
        return least, least
    return max(particles, configured), max(generations, configured)

