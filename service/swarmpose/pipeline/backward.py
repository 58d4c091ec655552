"""The backward pass of offline runs (the ``backward`` setting).

A track is worst at its start: the first frame's fit rests on one detection, and in a side view the
limbs the depth cannot place settle only over the following frames, as the motion shows them
(most of all in side views of fast motion: hops, jumps, turns, dance). A recording can be
tracked in both directions. So, every ``window`` frames, each person's track is run backwards over those frames,
starting from the last frame's solution, and each of those frames gets the backward fit where it
found the person. The backward tracker is a plain :class:`~swarmpose.tracking.body_tracker.BodyTracker`
with the forward tracker's settings and its body as it is at the window's end (a fitted height or
``--personalize`` shape included), fed each frame's own inputs as the forward tracker had them (a
person's depth with the other people taken out, their detection), in reverse.

Costs about twice the tracking time, and results come ``window`` frames late: offline only
(``track``, ``eval``, :func:`swarmpose.pipeline.api.track`); ``serve`` and ``replay`` publish live.
A frame the backward tracker loses keeps its forward fit, and so do a person's frames whose
backward run fails (logged) and the frames held when the run is stopped. Frames are held in memory
for a window (about 2 MB each at 640 x 480 with colour, and a depth copy per person with several
people). A limit: a person whose id is retired before their frames leave the window has a BVH
file (``--out``) written with the start body, since the sink asks for the id's body then.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

from swarmpose.body.skinned import SkinnedBody
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult, FrameResult

log = logging.getLogger(__name__)

SETTLED_AGE = 8
"""The backward tracker starts as a track this many frames old: past the young re-checks of the
facing (:data:`~swarmpose.tracking.facings.YOUNG_RECHECKS`), which exist for a start's doubtful
facing, not for a converged one."""


@dataclass(frozen=True)
class StepInput:
    """What one person's forward tracker was given for one frame, as it was then: the id, the body,
    camera, settings and OpenCL context it tracked with, the frame it saw (the other people's depth
    removed, where they were) and its 2D joints. (A tracker's body changes: a retired person's
    tracker goes back to the start body, and a spare tracker takes on another id.)"""

    body_id: int
    body: SkinnedBody
    tracker_config: TrackerConfig
    context: ClContext
    frame: Frame
    joints: Joints2D | None
    others_removed: bool


def person_steps(steps: Sequence[StepInput], results: Sequence[FrameResult]) -> dict[int, list[StepInput]]:
    """Per body id, in frame order, the steps whose fit that id published in ``results``: one per
    frame, the last for the id in that frame. A new person's tracker is tried under the next id on
    each unexplained segment and let go when it finds nobody there, so a frame may hold steps for
    an id that its result does not have, or before the step that gave the id its body."""
    published = {r.index: {b.id for b in r.bodies} for r in results}
    last: dict[tuple[int, int], StepInput] = {}
    for step in steps:
        if step.body_id in published.get(step.frame.index, ()):
            last[(step.frame.index, step.body_id)] = step
    out: dict[int, list[StepInput]] = {}
    for (_, body_id), step in sorted(last.items()):
        out.setdefault(body_id, []).append(step)
    return out


class BackwardPass:
    """Holds a run's frame results ``window`` frames and hands them on with each person's frames refit
    backwards (module doc). Use: :meth:`record` as every tracker's ``on_step``, :meth:`add` each
    result in order, :meth:`finish` at the end, :meth:`release` when the run stops or fails.
    stop: an event that, once set, ends a backward run in progress (the rest keep their forward fits)."""

    def __init__(self, window: int, stop: threading.Event | None = None):
        if window < 1:
            raise ValueError(f"a backward window of {window} frames; it needs at least 1")
        self.window, self.stop = int(window), stop
        self.results: list[FrameResult] = []
        self.steps: list[StepInput] = []
        self.refit_bodies: dict[tuple[int, int], SkinnedBody] = {}
        """The body each fit of the last window handed on was refit with, by (frame index, id) (the
        window's last step's body, which a height or shape locked in the window changes)."""
        self._tracker: BodyTracker | None = None  # the backward tracker, rebuilt for another camera or settings

    def record(self, tracker: BodyTracker, frame: Frame, joints: Joints2D | None, others_removed: bool) -> None:
        """A tracker's ``on_step``: keep its input for the backward pass."""
        self.steps.append(StepInput(tracker.body_id, tracker.body, tracker.config, tracker.objective.scorer.cl_context,
                                    frame, joints, others_removed))

    def add(self, result: FrameResult) -> list[FrameResult]:
        """Hold ``result``; the window's results, refit, once it holds ``window`` frames (else none)."""
        self.results.append(result)
        return self.flush() if len(self.results) >= self.window else []

    def finish(self) -> list[FrameResult]:
        """The results still held, refit."""
        return self.flush() if self.results else []

    def release(self) -> list[FrameResult]:
        """The results still held as the forward pass left them (the run stopped or failed)."""
        out, self.results, self.steps = self.results, [], []
        return out

    def flush(self) -> list[FrameResult]:
        """Refit the held frames backwards per person and hand them on, in order."""
        refit: dict[tuple[int, int], BodyResult] = {}
        self.refit_bodies = {}
        spent_ms: dict[int, float] = {}
        held = {r.index: r for r in self.results}
        for body_id, steps in person_steps(self.steps, self.results).items():
            try:
                refit.update(self._refit_person(body_id, steps, held, spent_ms))
            except Exception as exc:  # that person keeps the forward fits of this window
                log.warning("backward pass of person %d over frames %d-%d failed (%s: %s); their forward fits "
                            "stand", body_id, steps[0].frame.index, steps[-1].frame.index, type(exc).__name__, exc)
        out = []
        for result in self.release():
            if result.index in spent_ms:
                bodies = tuple(refit.get((result.index, b.id), b) for b in result.bodies)
                people = None if result.people is None else {
                    **result.people, "tracked": sum(b.state != "lost" for b in bodies)}
                result = replace(result, bodies=bodies, people=people,
                                 timings_ms={**result.timings_ms, "backward": spent_ms[result.index]})
            out.append(result)
        return out

    def _refit_person(self, body_id: int, steps: list[StepInput], held: dict[int, FrameResult],
                      spent_ms: dict[int, float]) -> dict[tuple[int, int], BodyResult]:
        """``body_id``'s ``steps`` run backwards from their last forward solution (``held``: the
        window's results by frame index): the fits by (frame index, id) of the frames it did not
        lose; the time spent per frame added to ``spent_ms``."""
        refit: dict[tuple[int, int], BodyResult] = {}
        forward = {}
        for step in steps:
            body = next(b for b in held[step.frame.index].bodies if b.id == body_id)
            if body.state != "lost" and body.pose is not None:
                forward[step.frame.index] = body
        last = max((k for k, s in enumerate(steps) if s.frame.index in forward), default=0)
        if last == 0:
            return refit
        tracker = self._tracker_for(steps[last])
        start = forward[steps[last].frame.index].pose
        tracker.previous, tracker.age = start.copy(), SETTLED_AGE
        tracker.history.restart(start.copy())
        tracker.body_id = body_id
        for step in reversed(steps[:last]):
            if self.stop is not None and self.stop.is_set():
                break
            t0 = time.perf_counter()
            body = tracker.step(step.frame, step.joints, step.others_removed)
            index = step.frame.index
            spent_ms[index] = spent_ms.get(index, 0.0) + 1000 * (time.perf_counter() - t0)
            if body.state != "lost":
                refit[(index, body_id)] = replace(body, reason=forward[index].reason if index in forward
                                                  else body.reason)
                self.refit_bodies[(index, body_id)] = tracker.body
        return refit

    def _tracker_for(self, step: StepInput) -> BodyTracker:
        """The backward tracker for ``step``'s camera, settings and body, its track forgotten."""
        tracker = self._tracker
        if (tracker is None or tracker.intrinsics != step.frame.intrinsics or tracker.config != step.tracker_config
                or tracker.objective.scorer.cl_context is not step.context):
            tracker = BodyTracker(step.body, step.frame.intrinsics, step.tracker_config, context=step.context)
            self._tracker = tracker
        elif tracker.body is not step.body:
            tracker.set_body(step.body)
        tracker.reset()
        return tracker
