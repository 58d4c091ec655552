"""``swarmpose serve``, ``replay``, ``health`` and ``subscribe``: the tracking service.

``serve`` runs the worker on a source and publishes over zenoh until the source ends (a
recording; ``--loop`` starts it over) or SIGINT/SIGTERM (a live camera is reopened when it
fails). ``replay`` runs the same pipeline over a recording as fast as it goes, without
dropping frames, writing poses.jsonl / poses.csv / poses.bvh / overlay.mp4, and prints Δ
and A(t) when the folder has ground truth. Settings: :mod:`swarmpose.config` (flags >
``SWARMPOSE_*`` > ``--config`` TOML > defaults).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

from . import messages
from .config import FIELDS, ServiceConfig, load_config
from .errors import ConfigError
from .progress import Progress

LOG_EVERY_S = 10.0


def add_service_options(p: argparse.ArgumentParser) -> None:
    """Flags of ``serve`` and ``replay``; each defaults to None so the config layers show through."""
    p.add_argument("--source", help="folder:DIR, bag:FILE, mkv:FILE, openni2:[FILE.oni], realsense:[SERIAL], "
                                    "azure:[INDEX], rgbd:C.png,D.png,K.json, or a folder ($SWARMPOSE_SOURCE)")
    p.add_argument("--camera-id", help="the <camera> of the zenoh keys swarmpose/<camera>/... (default camera0)")
    p.add_argument("--joints", help="2D joints: simulated | onnx:MODEL.onnx | openpose-json:DIR (default simulated)")
    p.add_argument("--body", help="builtin (default), makehuman:DIR or a .glb/.gltf file")
    p.add_argument("--shape", help="shape preset of the body (e.g. male, female, male-heavy)")
    p.add_argument("--mode", choices=("hybrid", "depth", "joints", "lift"), help="objective (default hybrid)")
    p.add_argument("--particles", type=int, help="PSO particles per generation (default 64)")
    p.add_argument("--generations", type=int, help="PSO generations per frame (default 64)")
    p.add_argument("--pso", choices=("perturbed", "canonical"), help="PSO variant (default perturbed)")
    p.add_argument("--tile", help="depth tile WxH over the person's box (default 64x64)")
    p.add_argument("--triangles", type=int, help="tracking level of detail (default 1500)")
    p.add_argument("--seed", type=int, help="PSO seed (default 0)")
    p.add_argument("--device", help="OpenCL device: cpu, gpu, P:D or part of its name")
    p.add_argument("--zenoh-mode", choices=("peer", "client", "off"),
                   help="zenoh: peer (default for serve), client (through a router) or off (default for replay)")
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   help="zenoh endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable)")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    p.add_argument("--no-multicast", dest="multicast", action="store_const", const=False, default=None,
                   help="turn zenoh multicast scouting off (no automatic discovery on the LAN)")
    p.add_argument("--zenoh-config", help="a zenoh JSON5 configuration file, applied before the flags")
    p.add_argument("--rate", type=float, help="deliver a recording at this many frames/s (serve default: as recorded)")
    p.add_argument("--max-frames", type=int, help="stop after this many frames (0 = all)")
    p.add_argument("--status-period", dest="status_period_s", type=float, help="seconds between status messages")
    p.add_argument("--health-file", help="also write each status message here (for `swarmpose health`)")
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")


def config_from_args(args: argparse.Namespace, defaults: dict | None = None) -> ServiceConfig:
    """The service configuration of parsed flags (None = not given) over env, file and defaults."""
    flags = {name: getattr(args, name) for name in FIELDS if hasattr(args, name)}
    for name in ("connect", "listen"):
        if flags.get(name) is not None:
            flags[name] = tuple(flags[name])
    return load_config(flags, config_file=args.config_file, defaults=defaults)


@dataclass
class Service:
    """A worker with what it was built from (see :func:`build_service`)."""

    config: ServiceConfig
    worker: object
    body: object
    source: object
    zenoh: object | None = None
    score: object | None = None
    outputs: list[Path] = field(default_factory=list)


def build_service(config: ServiceConfig, stack: ExitStack, *, replay: bool, out: str = "",
                  log=None, progress: bool = False) -> Service:
    """Open the source, detector, body, sinks and the worker of ``config``; ``stack`` closes the
    detector. replay: no dropped frames, no pacing, ``out`` gets the files."""
    from .joints2d.registry import make_detector
    from .messages import info_message
    from .model.loader import load_body
    from .pso import PsoConfig
    from .publish.files import open_recording
    from .publish.scoring import ScoreSink
    from .publish.zenoh_link import ZenohSink
    from .sources.registry import open_source
    from .tracker import Tracker, TrackerConfig
    from .worker import Worker

    config.require_source()
    uri = config.source  # open_source takes bare folders and recording files as well as URIs
    tracker_config = TrackerConfig(mode=config.mode, pso=PsoConfig(particles=config.particles,
                                                                   generations=config.generations, variant=config.pso),
                                   tile=config.tile_size, triangles=config.triangles, seed=config.seed,
                                   device=config.device or None)
    body = load_body(config.body, config.shape or None)
    source = open_source(uri)
    stack.callback(source.close)
    detector = make_detector(config.joints, source)
    stack.callback(detector.close)
    tracking_body = body if len(body.triangles) <= config.triangles else body.tracking_lod(config.triangles)
    fps = float(getattr(source, "fps", 0.0) or 30.0)
    service = Service(config, None, tracking_body, source)

    def info() -> dict:
        worker = service.worker
        return info_message(config.camera_id, intrinsics=getattr(worker, "intrinsics", None), body=tracking_body,
                            body_spec=config.body, source=uri, detector=config.joints, mode=config.mode,
                            opencl_device=getattr(worker, "opencl_device", ""))

    sinks: list = []
    if config.zenoh_mode != "off":
        service.zenoh = ZenohSink(config.camera_id, info, mode=config.zenoh_mode, connect=config.connect,
                                  listen=config.listen, multicast=config.multicast, config_file=config.zenoh_config,
                                  retry_s=config.reopen_s)
        stack.callback(service.zenoh.close)
        sinks.append(service.zenoh)
    folder = out or config.record
    if folder:
        recording = open_recording(Path(folder), tracking_body, fps=fps, overlay=config.overlay)
        for sink in recording:  # the worker closes them; this covers a failure before it runs
            stack.callback(sink.close)
        sinks.extend(recording)
        service.outputs = [Path(s.path) for s in recording]
    ground_truth = getattr(source, "ground_truth", None)
    if ground_truth is not None:
        service.score = ScoreSink(ground_truth)
        sinks.append(service.score)
    total = config.max_frames or source.length or 0
    if progress and total:
        sinks.append(ProgressSink(Progress("replay", total)))
    if replay:
        pace = config.rate or None
    else:
        pace = None if source.live else (config.rate or fps)
    service.worker = Worker(
        lambda: open_source(uri), detector, lambda intr: Tracker(body, intr, tracker_config), sinks,
        camera=config.camera_id, drop_stale=not replay, pace_fps=pace, loop=config.loop and not replay,
        max_frames=config.max_frames, status_period_s=config.status_period_s, reopen_s=config.reopen_s,
        source_uri=uri, detector_spec=config.joints, health_file=config.health_file,
        zenoh_state=service.zenoh.state if service.zenoh else None, log=log, source=source)
    return service


class ProgressSink:
    """Shows replay progress (frames published of the recording's length) on stderr."""

    def __init__(self, bar: Progress):
        self.bar, self.done = bar, 0

    def frame(self, message: dict, frame) -> None:
        self.done += 1
        self.bar.update(self.done)

    def status(self, message: dict) -> None:
        """Nothing to show per status."""

    def close(self) -> None:
        """Nothing to release."""


class ThrottledLog:
    """Prints status messages as lines on stderr: while running at most every ``every_s``
    seconds, and every one once the worker is ending (its last words)."""

    def __init__(self, every_s: float = LOG_EVERY_S):
        self.every_s, self._last = every_s, -float("inf")

    def __call__(self, status: dict) -> None:
        from .worker import format_status

        now = time.monotonic()
        if status["state"] not in ("starting", "running") or now - self._last >= self.every_s:
            self._last = now
            print(format_status(status), file=sys.stderr, flush=True)


def _stop_on_signals(worker, stack: ExitStack) -> None:
    """SIGINT and SIGTERM stop ``worker``; ``stack`` puts the previous handlers back."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous = signal.signal(sig, lambda *_: worker.stop())
        stack.callback(signal.signal, sig, previous)


def cmd_serve(args: argparse.Namespace) -> int:
    """Run the worker and publish over zenoh until the source ends or a signal comes."""
    config = config_from_args(args)
    with ExitStack() as stack:
        service = build_service(config, stack, replay=False, log=ThrottledLog())
        _stop_on_signals(service.worker, stack)
        keys = ", ".join(messages.keys(config.camera_id).values())
        where = f"zenoh {config.zenoh_mode}" + (f", connect {', '.join(config.connect)}" if config.connect else "") + (
            f", listen {', '.join(config.listen)}" if config.listen else "")
        print(f"swarmpose serve: {service.worker.source_uri} -> {keys} ({where}); Ctrl-C stops", file=sys.stderr)
        service.worker.run()
    return 1 if service.worker.state in ("source-failed", "failed") else 0


def cmd_replay(args: argparse.Namespace) -> int:
    """Track a recording frame by frame into files; Δ and A(t) when it has ground truth."""
    config = config_from_args(args, defaults={"zenoh_mode": "off"})
    with ExitStack() as stack:
        service = build_service(config, stack, replay=True, out=args.out, progress=not args.quiet)
        _stop_on_signals(service.worker, stack)
        started = time.monotonic()
        stats = service.worker.run()
    seconds = time.monotonic() - started
    result = replay_summary(service, stats, seconds)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_replay_summary(result))
    return 1 if service.worker.state in ("source-failed", "failed") else 0


def replay_summary(service: Service, stats, seconds: float) -> dict:
    """What a replay produced: counts, fps, latency, Δ / A(t) (with ground truth), output files and sizes."""
    from .worker import latency_summary

    result = {"frames": stats.published, "skipped": stats.skipped, "failed": stats.failed,
              "fps": round(stats.published / seconds, 3) if seconds > 0 else 0.0,
              "latency_ms": {k: None if v is None else round(v, 1)
                             for k, v in latency_summary(stats.all_latencies).items()},
              "outputs": {str(p): p.stat().st_size for p in service.outputs if p.exists()},
              "opencl_device": service.worker.opencl_device, "state": service.worker.state}
    if service.score is not None and service.score.estimates:
        summary = service.score.summary()
        result.update({"mpjpe_mm": summary["mpjpe_mm"], "coverage": summary["coverage"],
                       "A": {str(t): a for t, a in summary["A"].items()}})
    return result


def format_replay_summary(result: dict) -> str:
    """Human-readable lines of :func:`replay_summary`."""
    lat = result["latency_ms"]
    lines = [f"{result['frames']} frames ({result['skipped']} skipped, {result['failed']} failed) at "
             f"{result['fps']:.2f} frames/s; latency median {lat['median']} ms, p95 {lat['p95']} ms"]
    if "mpjpe_mm" in result:
        delta = "n/a" if result["mpjpe_mm"] is None else f"{result['mpjpe_mm']:.1f} mm"
        lines.append(f"Δ = {delta}, A(100 mm) = {100 * result['A']['100']:.0f}%, coverage {result['coverage']:.0%}")
        lines.append("A(t): " + "  ".join(f"{t}mm {100 * a:.0f}%" for t, a in result["A"].items()))
    for path, size in result["outputs"].items():
        lines.append(f"  {path}  {size:,} bytes")
    return "\n".join(lines)


def cmd_health(args: argparse.Namespace) -> int:
    """Exit 0 when the worker's status file is fresh and it is running, 1 otherwise (docker HEALTHCHECK)."""
    try:
        path = args.file or load_config({}).health_file
    except ConfigError as exc:  # exit 1, not 2: docker reserves 2 in health checks
        print(f"unhealthy: {exc}")
        return 1
    if not path:
        print("unhealthy: no status file: pass --file or set SWARMPOSE_HEALTH_FILE (the worker writes it)")
        return 1
    try:
        status = json.loads(Path(path).read_text(encoding="utf-8"))
        age = (time.time_ns() - int(status["time_ns"])) / 1e9
        state = status["state"]
    except FileNotFoundError:
        print(f"unhealthy: no status in {path} yet (the worker has not run a status period)")
        return 1
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"unhealthy: {path} is not a status message ({exc})")
        return 1
    if age > args.max_age:
        print(f"unhealthy: last status {age:.1f} s old (> {args.max_age:g} s); the worker is stuck or gone")
        return 1
    if state not in ("starting", "running"):
        print(f"unhealthy: worker state {state} (source {status['source']['state']})")
        return 1
    print(f"healthy: {state}, {status['fps']:.2f} fps, source {status['source']['state']}")
    return 0


def cmd_subscribe(args: argparse.Namespace) -> int:
    """Print poses as they arrive (the client's command line)."""
    from .client import main

    return main(args.rest)


def add_service_commands(sub) -> None:
    """Register ``serve``, ``replay``, ``health`` and ``subscribe``."""
    p = sub.add_parser("serve", help="track a camera or recording and publish over zenoh (long-running)")
    add_service_options(p)
    p.add_argument("--loop", action="store_const", const=True, default=None,
                   help="start a recording over when it ends")
    p.add_argument("--record", help="also write poses.jsonl/csv/bvh and overlay.mp4 into this folder")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("replay", help="track a recording into poses.jsonl/csv/bvh + overlay.mp4 (Δ, A(t) with "
                                      "ground truth)")
    add_service_options(p)
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--no-overlay", dest="overlay", action="store_const", const=False, default=None,
                   help="do not write overlay.mp4")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("health", help="exit 0 if the worker's status file is fresh and it runs (docker HEALTHCHECK)")
    p.add_argument("--file", default=None, help="the status file (default $SWARMPOSE_HEALTH_FILE)")
    p.add_argument("--max-age", type=float, default=15.0, help="seconds after which a status counts as stale")
    p.set_defaults(func=cmd_health)

    p = sub.add_parser("subscribe", help="print poses published by workers (see swarmpose.client)", add_help=False)
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=cmd_subscribe)
