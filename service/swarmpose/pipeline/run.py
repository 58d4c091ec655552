"""The sequential run: every frame of a source through the per-frame step, in one thread.

``swarmpose track`` and ``eval``, and :func:`swarmpose.track`, use it. Each frame's
result goes, as the protocol's frame message, to every sink (files, scoring, ...) before
the next frame is read, so an interrupted run keeps everything it produced (with the
``backward`` setting, a window's frames go after its backward pass, and with centred smoothing
3σ of frames are held; a stop or an error hands on those held first). A sink that
fails is logged and dropped; the others go on. A source that ends with ``status`` ``"error: …"``
(a recording that breaks, a camera that vanishes) is logged as a warning and, in a
:class:`RunSummary`, kept as ``source_error``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

from swarmpose.core.progress import progress_bar
from swarmpose.pipeline.backward import BackwardPass
from swarmpose.pipeline.centred_smoothing import CentredSmoother
from swarmpose.pipeline.step import FramePipeline, describe_error
from swarmpose.publish.sink import Sink
from swarmpose.sources.base import Frame, SkippedFrame
from swarmpose.tracking.result import FrameResult

log = logging.getLogger(__name__)
_END = object()


@dataclass
class RunSummary:
    """What a run went through: frames, counts per state (init / tracking / lost / skipped),
    the wall time (s) of detection + tracking, the errors of sinks that failed, and the
    source's ``"error: …"`` status when it ended by failing ('' when it did not); interrupted:
    a stop request ended it before the source did; nobody_reason: the reason of the first
    frame read in which nobody was found ('' while there is none)."""

    frames: int = 0
    states: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    sink_errors: list[str] = field(default_factory=list)
    source_error: str = ""
    interrupted: bool = False
    nobody_reason: str = ""

    @property
    def fps(self) -> float:
        """Frames per second of detection + tracking (file reading excluded)."""
        tracked = sum(v for k, v in self.states.items() if k != "skipped")
        return tracked / self.seconds if self.seconds > 0 else 0.0

    @property
    def tracked(self) -> int:
        """Frames in which a body was found (state init or tracking)."""
        return sum(v for k, v in self.states.items() if k not in ("lost", "skipped"))

    def count(self, result: FrameResult, seconds: float) -> None:
        if not (result.skipped or result.bodies or self.nobody_reason):
            self.nobody_reason = f"frame {result.index}: {result.reason}"
        self.frames += 1
        self.states[result.state] = self.states.get(result.state, 0) + 1
        self.seconds += seconds


def results(source: Iterable[Frame | SkippedFrame], pipeline: FramePipeline, frames: int = 0,
            summary: RunSummary | None = None, stop: threading.Event | None = None) -> Iterator[FrameResult]:
    """The result of every item of ``source`` (at most ``frames``; 0 = all), counted in ``summary``.
    No item is read past the ``frames``-th, nor once ``stop`` is set (``summary.interrupted``). With
    the pipeline's ``backward`` window, each window's results come after its backward pass
    (:mod:`swarmpose.pipeline.backward`), counted with its time; when the items end, the last ones;
    when the run is stopped or fails, those held as the forward pass left them. With its
    ``centred_sigma_s``, the results (after the backward pass) come 3σ late with their poses smoothed
    (:mod:`swarmpose.pipeline.centred_smoothing`); a stop smooths the frames held with those there
    are, a failure hands them on as found."""
    summary = summary if summary is not None else RunSummary()
    refiner = BackwardPass(pipeline.backward, stop) if pipeline.backward else None
    if refiner is not None:
        pipeline.on_step = refiner.record
    smoother = CentredSmoother(pipeline.centred_sigma_s) if pipeline.centred_sigma_s else None
    seconds: dict[int, float] = {}  # each result's forward time until it is counted

    def smoothed(done: list[FrameResult]) -> list[FrameResult]:
        if smoother is None:
            return done
        if refiner is not None and done:  # a window just refit: the bodies the backward pass used
            smoother.note_refits(refiner.refit_bodies, pipeline.intrinsics)
        return [out for result in done for out in smoother.add(result)]

    items, read = iter(source), 0
    try:
        while not (frames and read >= frames):
            if stop is not None and stop.is_set():
                summary.interrupted = True
                break
            item = next(items, _END)
            if item is _END:
                break
            read += 1
            t0 = time.perf_counter()
            result = pipeline.process(item)
            seconds[result.index] = 0.0 if result.skipped else time.perf_counter() - t0
            if smoother is not None:
                smoother.note_bodies(result, pipeline.body_of, pipeline.intrinsics)
            yield from _counted(smoothed([result] if refiner is None else refiner.add(result)), seconds, summary)
        if refiner is not None:
            done = refiner.release() if summary.interrupted else refiner.finish()
            yield from _counted(smoothed(done), seconds, summary)
        if smoother is not None:
            yield from _counted(smoother.finish(), seconds, summary)
    except Exception:
        held = [] if smoother is None else smoother.release()  # the earlier frames: as found, then the error
        if refiner is not None:  # what was held goes out as the forward pass left it
            held += refiner.release()
        yield from _counted(held, seconds, summary)
        raise


def _counted(done: list[FrameResult], seconds: dict[int, float], summary: RunSummary) -> Iterator[FrameResult]:
    """``done`` (results handed on, after the backward pass and the smoothing if any) counted in
    ``summary`` with their forward time from ``seconds``, their backward time and their smoothing's."""
    for result in done:
        extra_ms = result.timings_ms.get("backward", 0.0) + result.timings_ms.get("smoothing", 0.0)
        summary.count(result, seconds.pop(result.index, 0.0) + extra_ms / 1000)
        yield result


def run_sequence(source: Iterable[Frame | SkippedFrame], pipeline: FramePipeline, sinks: Sequence[Sink] = (), *,
                 camera: str = "camera0", frames: int = 0, progress: bool = True,
                 stop: threading.Event | None = None, label: str = "track") -> RunSummary:
    """Track ``source`` frame by frame, handing each frame message to ``sinks``; closes the sinks.
    ``label``: the progress bar's (the command's name).
    ``stop`` (set from a signal handler) ends the run after the frame in progress, which every
    sink gets, so the files hold the same frames (with the backward pass, the frames it held go
    out with their forward fits)."""
    summary = RunSummary()
    live = list(sinks)
    total = frames or getattr(source, "length", None) or None
    try:
        with progress_bar(label, total, enabled=progress) as bar:
            frames_of = {}
            for result in results(remember_frames(source, frames_of), pipeline, frames, summary, stop):
                message = result.to_message(camera)
                frame = frames_of.pop(result.index, None)
                for sink in list(live):
                    try:
                        sink.frame(message, frame)
                    except Exception as exc:  # one failing sink must not stop the run or the others
                        what = f"{type(sink).__name__}: {describe_error(exc)}"
                        log.error("%s; it gets no more frames", what)
                        summary.sink_errors.append(what)
                        live.remove(sink)
                bar.update(1)
        summary.source_error = "" if summary.interrupted else source_error(source)
        if summary.frames and not summary.tracked and summary.nobody_reason:
            log.warning("nobody was tracked in the %d frames read (%s); each frame's message says why",
                        summary.frames, summary.nobody_reason)
    finally:
        for sink in sinks:
            try:
                sink.close()
            except Exception as exc:  # report, close the others
                log.error("closing %s: %s", type(sink).__name__, describe_error(exc))
    return summary


def source_error(source: object) -> str:
    """The ``"error: …"`` status a source ended with, logged as a warning naming it; '' otherwise."""
    status = str(getattr(source, "status", "") or "")
    if not status.startswith("error"):
        return ""
    log.warning("source %s ended with an error: %s", getattr(source, "uri", "") or type(source).__name__,
                status.removeprefix("error:").strip())
    return status


def remember_frames(source: Iterable[Frame | SkippedFrame], frames_of: dict) -> Iterator[Frame | SkippedFrame]:
    """Pass ``source`` through, keeping each Frame by index until its message is handed out."""
    for item in source:
        if isinstance(item, Frame):
            frames_of[item.index] = item
        yield item
