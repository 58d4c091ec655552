"""The backward pass of offline runs (the ``backward`` setting).

A track is worst at its start: the first frame's fit rests on one detection, and in a side view the
limbs the depth cannot place settle only over the following frames, as the motion shows them
(the hop, the jumps and turns and the dance seen from the side: 100-220 mm at the start, 35-50 mm
twenty frames later; BENCHMARKS.md, issue 12, fifteenth part). A recording can be tracked in both
directions. So, every ``window`` frames, each person's track is run backwards over those frames,
starting from the last frame's solution, and each of those frames gets the backward fit where it
found the person. The backward tracker is a plain :class:`~swarmpose.tracking.body_tracker.BodyTracker`
with the forward tracker's settings and its body as it is at the window's end (a fitted height or
``--personalize`` shape included), fed each frame's own inputs as the forward tracker had them (a
person's depth with the other people taken out, their detection), in reverse.

Costs about twice the tracking time, and results come ``window`` frames late: offline only
(``track``, ``eval``, :func:`swarmpose.pipeline.api.track`); ``serve`` and ``replay`` publish live.
A frame the backward tracker loses keeps its forward fit. Frames are held in memory for a window
(about 2 MB each at 640 x 480 with colour).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

from swarmpose.detect.joints import Joints2D
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.result import BodyResult, FrameResult

SETTLED_AGE = 8
"""The backward tracker starts as a track this many frames old: past the young re-checks of the
facing (:data:`~swarmpose.tracking.body_tracker.YOUNG_RECHECKS`), which exist for a start's doubtful
facing, not for a converged one."""


@dataclass(frozen=True)
class StepInput:
    """What one person's forward tracker was given for one frame: its id then, the tracker, the
    frame it saw (the other people's depth removed, where they were) and its 2D joints."""

    body_id: int
    tracker: BodyTracker
    frame: Frame
    joints: Joints2D | None
    others_removed: bool


class BackwardPass:
    """Holds a run's frame results ``window`` frames and hands them on with each person's frames refit
    backwards (module doc). Use: :meth:`record` as every tracker's ``on_step``, :meth:`add` each
    result in order, :meth:`finish` at the end (or when the run stops early)."""

    def __init__(self, window: int):
        if window < 1:
            raise ValueError(f"a backward window of {window} frames; it needs at least 1")
        self.window = int(window)
        self.results: list[FrameResult] = []
        self.steps: list[StepInput] = []
        self._backward: dict[int, BodyTracker] = {}  # id(forward tracker) -> its backward tracker

    def record(self, tracker: BodyTracker, frame: Frame, joints: Joints2D | None, others_removed: bool) -> None:
        """A tracker's ``on_step``: keep its input for the backward pass."""
        self.steps.append(StepInput(tracker.body_id, tracker, frame, joints, others_removed))

    def add(self, result: FrameResult) -> list[FrameResult]:
        """Hold ``result``; the window's results, refit, once it holds ``window`` frames (else none)."""
        self.results.append(result)
        return self.flush() if len(self.results) >= self.window else []

    def finish(self) -> list[FrameResult]:
        """The results still held, refit."""
        return self.flush() if self.results else []

    def release(self) -> list[FrameResult]:
        """The results still held as the forward pass left them (the run failed)."""
        out, self.results, self.steps = self.results, [], []
        return out

    def flush(self) -> list[FrameResult]:
        """Refit the held frames backwards per person and hand them on, in order."""
        held = {r.index: i for i, r in enumerate(self.results)}
        by_person: dict[int, list[StepInput]] = {}
        for step in self.steps:
            if step.frame.index in held:
                by_person.setdefault(step.body_id, []).append(step)
        refit: dict[tuple[int, int], BodyResult] = {}
        spent_ms: dict[int, float] = {}
        for body_id, steps in by_person.items():
            self._refit_person(body_id, steps, held, refit, spent_ms)
        out = []
        for result in self.results:
            bodies = tuple(refit.get((result.index, b.id), b) for b in result.bodies)
            if result.index in spent_ms:
                timings = {**result.timings_ms, "backward": spent_ms[result.index]}
                result = replace(result, bodies=bodies, timings_ms=timings)
            out.append(result)
        self.results, self.steps = [], []
        return out

    def _refit_person(self, body_id: int, steps: list[StepInput], held: dict[int, int],
                      refit: dict[tuple[int, int], BodyResult], spent_ms: dict[int, float]) -> None:
        """Run ``body_id``'s frames backwards from their last forward solution into ``refit``."""
        forward = {}
        for step in steps:
            body = next((b for b in self.results[held[step.frame.index]].bodies if b.id == body_id), None)
            if body is not None and body.state != "lost" and body.pose is not None:
                forward[step.frame.index] = body
        last = max((k for k, s in enumerate(steps) if s.frame.index in forward), default=None)
        if last is None or last == 0:
            return
        tracker = self._tracker_for(steps[last].tracker)
        start = forward[steps[last].frame.index].pose
        tracker.previous, tracker.history, tracker.age = start.copy(), [start.copy()], SETTLED_AGE
        tracker.body_id = body_id
        for step in reversed(steps[:last]):
            t0 = time.perf_counter()
            try:
                body = tracker.step(step.frame, step.joints, step.others_removed)
            except Exception:  # the forward fit stands; the backward track restarts on the frame before
                tracker.reset()
                continue
            finally:
                index = step.frame.index
                spent_ms[index] = spent_ms.get(index, 0.0) + 1000 * (time.perf_counter() - t0)
            if body.state != "lost":
                reason = forward[step.frame.index].reason if step.frame.index in forward else body.reason
                refit[(step.frame.index, body_id)] = replace(body, reason=reason)

    def _tracker_for(self, forward: BodyTracker) -> BodyTracker:
        """The backward tracker of ``forward``: its settings, its body now, its OpenCL context."""
        tracker = self._backward.get(id(forward))
        if tracker is None:
            context = forward.objective.scorer.cl_context
            tracker = BodyTracker(forward.body, forward.intrinsics, forward.config, context=context)
            self._backward[id(forward)] = tracker
        elif tracker.body is not forward.body:
            tracker.set_body(forward.body)
        tracker.reset()
        return tracker
