"""Assembling a run from its settings: body, source, detector, per-frame step and sinks.

:func:`open_parts` gives what every command needs (:class:`Parts`); :func:`build_worker`
adds zenoh, files, scoring and status sinks around a :class:`~.worker.Worker`
(``serve``: live hand-overs, paced; ``replay``: every frame, as fast as it goes), and
:func:`run_summary` reports what a run produced. Every opened part is closed by the
caller's ``ExitStack``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from swarmpose.body.loader import load_body
from swarmpose.body.shape_space import shape_space_for
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError
from swarmpose.core.progress import progress_bar
from swarmpose.detect.joints import Detector
from swarmpose.detect.registry import detector_note, make_detector, resolve_detector
from swarmpose.messages.build import info_message
from swarmpose.pipeline.builder import build_pipeline
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.features import refuse
from swarmpose.pipeline.status import HealthFileSink, LogSink, WorkerStats, latency_summary
from swarmpose.pipeline.step import FramePipeline
from swarmpose.pipeline.worker import Worker
from swarmpose.publish.files import open_recording
from swarmpose.publish.rerun_view import open_view_sink
from swarmpose.publish.run_file import write_run_file
from swarmpose.publish.sink import Sink
from swarmpose.publish.zenoh_link import ZenohSink
from swarmpose.sim.scoring import ScoreSink
from swarmpose.sources.base import DeferredFrame, Frame, FrameSource, SkippedFrame
from swarmpose.sources.registry import open_source
from swarmpose.tracking.budget import live_budget_ms

if TYPE_CHECKING:
    from swarmpose.pipeline.ensemble import EnsemblePipeline

log = logging.getLogger(__name__)


@dataclass
class Parts:
    """What a run is made of: the settings, the tracking body, the open source, the
    detector, the per-frame step, the sinks, the ground-truth scorer (None: no ground
    truth) and the files it writes."""

    config: ServiceConfig
    body: SkinnedBody
    source: FrameSource
    detector: Detector
    pipeline: FramePipeline | EnsemblePipeline
    sinks: list[Sink] = field(default_factory=list)
    score: ScoreSink | None = None
    recording: list[Sink] = field(default_factory=list)

    @property
    def outputs(self) -> list[Path]:
        """The files the recording sinks write so far (a BVH per id appears with its person)."""
        return [Path(p) for s in self.recording for p in (getattr(s, "paths", None) or [s.path])]

    @property
    def fps(self) -> float:
        """The source's frame rate (30 when it does not say)."""
        return float(getattr(self.source, "fps", 0.0) or 30.0)


def warn_of_another_body(source: FrameSource, body: SkinnedBody, config: ServiceConfig) -> None:
    """A warning when ``source`` was rendered with another body than the one tracking it (a
    ``swarmpose synth`` sequence records its body in ``sequence.json``): the shape mismatch
    then adds to every joint error."""
    recorded = getattr(source, "recorded_body", "")
    if recorded and recorded != body.name and config.tracker.personalize == 0:
        log.warning("%s was rendered with the body %s, and is tracked with %s (--body %s%s): the errors include "
                    "the difference of shape; pass the recorded body (e.g. --body makehuman:DIR --shape NAME) to "
                    "measure the tracker alone", source.uri, recorded, body.name, config.body,
                    f" --shape {config.shape}" if config.shape else "")


def run_record(config: ServiceConfig, requested: str, detector: Detector) -> dict:
    """What ``run.json`` says of a run (:mod:`swarmpose.publish.run_file`)."""
    from dataclasses import asdict

    from swarmpose import __version__

    path = getattr(detector, "path", None)
    return {"swarmpose": __version__, "source": config.source, "detector_requested": requested,
            "detector": getattr(detector, "name", type(detector).__name__), "model": str(path) if path else None,
            "body": config.body, "shape": config.shape, "coordinates": config.coordinates, "floor": config.floor,
            "tracker": asdict(config.tracker)}


def open_parts(config: ServiceConfig, stack: ExitStack, *, out: str = "", score: bool = True,
               need_ground_truth: bool = False, driver: str = "offline") -> Parts:
    """Open the source, detector and body of ``config`` (closed by ``stack``) and the pipeline of
    ``driver`` (:func:`~swarmpose.pipeline.builder.build_pipeline`); with ``out``, the replay files
    there; with ``score`` and a source that has ground truth, a scorer. need_ground_truth:
    ConfigError at once (before any file is written) for a source without; a feature ``driver``
    cannot run is refused before anything is opened."""
    refuse(driver, config.tracker)
    config.require_source()
    space = None
    if config.tracker.personalize > 0:  # the body is fitted online: track with the space's start body
        if config.tracker.mode == "lift":
            raise ConfigError("--personalize needs a body model; the lift mode fits none (use hybrid, depth or joints)")
        space = shape_space_for(config.body, config.shape, config.tracker.triangles)
        body = space.tracking_body(space.start)
    else:
        body = load_body(config.body, config.shape or None)
    source = open_source(config.source)
    stack.callback(source.close)
    requested = config.detector
    config = replace(config, detector=resolve_detector(config.detector, source))  # what "auto" picked
    detector = make_detector(config.detector, source, config.models)
    stack.callback(detector.close)
    log.info("%s", detector_note(requested, detector))
    warn_of_another_body(source, body, config)
    ground_truth = getattr(source, "ground_truth", None)
    if need_ground_truth and ground_truth is None:
        raise ConfigError(f"{config.source} has no ground truth (groundtruth.jsonl): eval needs a sequence folder "
                          "written by `swarmpose synth`; use `swarmpose track` for other sources")
    triangles = config.tracker.triangles
    tracking_body = body if len(body.triangles) <= triangles else body.tracking_lod(triangles)
    pipeline = build_pipeline(driver, tracking_body, detector, config.tracker, body_spec=config.body,
                              shape=config.shape, space=space, floor=config.floor, coordinates=config.coordinates)
    parts = Parts(config, tracking_body, source, detector, pipeline)
    if out:
        # the bodies that --personalize or the automatic height change (those the pipeline reports on)
        body_of = parts.pipeline.body_of if parts.pipeline.personalise_frames else None
        recording = open_recording(Path(out), tracking_body, fps=parts.fps, overlay=config.overlay, body_of=body_of,
                                   ros_bag=config.ros_bag, ros_depth=config.ros_depth)
        for sink in recording:  # the run closes them; this covers a failure before it starts
            stack.callback(sink.close)
        parts.sinks.extend(recording)
        parts.recording = recording
        write_run_file(out, run_record(config, requested, detector))
    view = open_view_sink(config.camera_id, rrd=config.rrd, view=config.view, url=config.view_url,
                          port=config.view_port, live=source.live)
    if view is not None:  # the rerun viewer / .rrd (--view, --rrd)
        stack.callback(view.close)
        parts.sinks.append(view)
        parts.recording += [view] if config.rrd else []
    if score and ground_truth is not None:
        parts.score = ScoreSink(ground_truth)
        parts.sinks.append(parts.score)
    return parts


class ProgressSink:
    """Shows progress (frames published of the recording's length) on stderr."""

    def __init__(self, label: str, total: int | None):
        self.bar = progress_bar(label, total)

    def frame(self, message: dict, frame: Frame | None) -> None:
        self.bar.update(1)

    def status(self, message: dict) -> None:
        """Nothing to show per status."""

    def close(self) -> None:
        self.bar.close()


def build_worker(config: ServiceConfig, stack: ExitStack, *, replay: bool, out: str = "",
                 progress: bool = False, sinks: Sequence[Sink] = (),
                 on_acquired: Callable[[Frame | SkippedFrame | DeferredFrame, int], None] | None = None,
                 ) -> tuple[Worker, Parts, ZenohSink | None]:
    """The worker of ``config`` with its sinks: zenoh (unless ``zenoh_mode`` is off), the replay
    files (``out`` or ``record``), the ground-truth scorer, the log, the health file, (with
    ``progress``) a progress bar, and last the caller's ``sinks``. replay: no dropped frames, no
    pacing, no looping. on_acquired: the worker's observer of the frames it takes from the source."""
    parts = open_parts(config, stack, out=out or config.record, driver="threaded")
    worker: Worker | None = None

    def info() -> dict:  # zenoh's thread: only references and the stats' snapshot are read here
        tracker = parts.pipeline.tracker
        snapshot = worker.stats.personalisation if worker is not None else {}  # the tracking thread's copy
        return info_message(config.camera_id, intrinsics=parts.pipeline.intrinsics,
                            body=tracker.body if tracker is not None else parts.body,
                            body_spec=config.body, source=config.source, detector=parts.config.detector,
                            mode=config.tracker.mode, opencl_device=parts.pipeline.device_name,
                            personalisation=snapshot or None,
                            world=None if parts.pipeline.world is None else parts.pipeline.world.info())

    zenoh = None
    z = config.zenoh
    if z.zenoh_mode != "off":
        zenoh = ZenohSink(config.camera_id, info, mode=z.zenoh_mode, connect=z.connect, listen=z.listen,
                          multicast=z.multicast, config_file=z.zenoh_config, retry_s=config.reopen_s)
        stack.callback(zenoh.close)
    extra = list(sinks)
    sinks: list[Sink] = ([zenoh] if zenoh else []) + parts.sinks + [LogSink()]
    if config.health_file:
        sinks.append(HealthFileSink(config.health_file))
    total = config.frames or parts.source.length or None
    if progress:
        sinks.append(ProgressSink("replay", total))
    sinks += extra
    if replay:
        pace = config.rate or None
    else:
        pace = None if parts.source.live else (config.rate or parts.fps)
        if pace and not config.rate and not (parts.source.rate_known and getattr(parts.source, "fps", 0)):
            log.warning("%s records no frame rate (a sequence folder keeps it in sequence.json's \"fps\"); serving "
                        "it at %g frames/s, its frames stamped so; pass --rate to serve it at another", config.source,
                        parts.fps)
        parts.pipeline.frame_period_s = 1.0 / parts.fps  # live: keep up with the camera
        parts.pipeline.budget_ms = live_budget_ms(config.frame_budget_ms, 1.0 / (pace or parts.fps))  # as frames come
    uri = config.source
    worker = Worker(lambda: open_source(uri), parts.pipeline, sinks, camera=config.camera_id, drop_stale=not replay,
                    pace_fps=pace, loop=config.loop and not replay, frames=config.frames,
                    status_period_s=config.status_period_s, reopen_s=config.reopen_s, source_uri=uri,
                    detector_spec=parts.config.detector, zenoh_state=zenoh.state if zenoh else None,
                    source=parts.source, on_acquired=on_acquired)
    return worker, parts, zenoh


def run_summary(parts: Parts, stats: WorkerStats, seconds: float, worker: Worker) -> dict:
    """What a worker run produced: counts, fps, latency, Δ / A(t) (with ground truth), output files and sizes."""
    result = {"frames": stats.published, "skipped": stats.skipped, "failed": stats.failed,
              "fps": round(stats.published / seconds, 3) if seconds > 0 else 0.0,
              "latency_ms": {k: None if v is None else round(v, 1)
                             for k, v in latency_summary(stats.all_latencies).items()},
              "outputs": {str(p): p.stat().st_size for p in parts.outputs if p.exists()},
              "opencl_device": worker.opencl_device, "state": worker.state, "sink_errors": list(worker.sink_errors)}
    result.update(score_summary(parts))
    return result


def score_summary(parts: Parts) -> dict:
    """``mpjpe_mm``, ``coverage`` and ``A`` (threshold mm as text -> share) when the run was scored."""
    if parts.score is None or not parts.score.bodies:
        return {}
    summary = parts.score.summary()
    out = {"mpjpe_mm": summary["mpjpe_mm"], "coverage": summary["coverage"],
           "A": {str(t): a for t, a in summary["A"].items()}, "per_joint_mm": summary["per_joint_mm"]}
    if parts.score.several:
        out["people"] = parts.score.people_summary()
    return out


def format_summary(result: dict) -> str:
    """Human-readable lines of :func:`run_summary`."""
    lat = result["latency_ms"]
    lines = [f"{result['frames']} frames ({result['skipped']} skipped, {result['failed']} failed) at "
             f"{result['fps']:.2f} frames/s; latency median {lat['median']} ms, p95 {lat['p95']} ms"]
    lines += format_accuracy(result)
    for path, size in result["outputs"].items():
        lines.append(f"  {path}  {size:,} bytes")
    lines += [f"  failed (nothing more written to it): {error}" for error in result.get("sink_errors", ())]
    return "\n".join(lines)


def format_accuracy(result: dict) -> list[str]:
    """Δ and A(t) lines of a summary that has them."""
    if "mpjpe_mm" not in result:
        return []
    delta = "n/a" if result["mpjpe_mm"] is None else f"{result['mpjpe_mm']:.1f} mm"
    lines = [f"Δ = {delta}, A(100 mm) = {100 * result['A']['100']:.0f}%, coverage {result['coverage']:.0%}",
             "A(t): " + "  ".join(f"{t}mm {100 * a:.0f}%" for t, a in result["A"].items())]
    people = result.get("people")
    if people:
        lines[0] = f"first person: {lines[0]}"
        lines.append(f"people: MOTA {people['mota']:.3f}, IDF1 {people['idf1']:.3f}, {people['id_switches']} "
                     f"identity switches, {people['misses']} misses, {people['false_positives']} false positives")
        for pid, p in people["per_person"].items():
            d = "n/a" if p["mpjpe_mm"] is None else f"{p['mpjpe_mm']:.1f} mm"
            lines.append(f"  person {pid}: Δ {d}, matched {p['matched_frames']}/{p['visible_frames']} visible "
                         f"frames, longest loss {p['longest_lost_run']} frames, ids {p['ids']}")
    return lines
