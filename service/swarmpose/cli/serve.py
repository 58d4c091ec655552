"""``swarmpose serve``, ``replay`` and ``health``: the tracking service.

``serve`` runs the worker on a source and publishes over zenoh until the source ends (a
recording; ``--loop`` starts it over) or SIGINT/SIGTERM (a live camera is reopened when it
fails). ``replay`` runs the same pipeline over a recording as fast as it goes, without
dropping frames, writing poses.jsonl / poses.csv / poses.bvh / overlay.mp4 into ``--out``
(so it takes no ``--loop`` or ``--record``), and prints Δ and A(t) when the folder has ground
truth; it exits 1 when the recording broke or a file could not be written (what was written
stays), 130 when SIGINT/SIGTERM stopped it. Settings: :mod:`swarmpose.cli.settings` (flags >
``SWARMPOSE_*`` > ``--config`` TOML > defaults).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING

from swarmpose.cli.common import DEFAULTS, INTERRUPTED, INTERRUPTED_NOTE, quiet, seconds, stop_on_signals
from swarmpose.cli.settings import add_flags, load
from swarmpose.cli.track import add_source_argument, settings_of
from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import leaves
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.features import unavailable_settings

if TYPE_CHECKING:  # the worker and the protocol are imported by the commands that run them
    from swarmpose.pipeline.worker import Worker

REPLAY_DEFAULTS = {"zenoh_mode": "off"}
SERVE_SETTINGS = tuple(name for name in leaves(ServiceConfig) if name not in unavailable_settings("threaded"))
"""The settings ``serve`` takes: all but the features its driver cannot run (:mod:`swarmpose.pipeline.features`)."""
REPLAY_SETTINGS = tuple(name for name in SERVE_SETTINGS if name not in ("loop", "record", "frame_budget_ms"))
"""The settings ``replay`` takes: it writes into ``--out``, ends with the recording and tracks every frame
with the full search."""
def cmd_serve(args: argparse.Namespace) -> int:
    """Run the worker and publish over zenoh until the source ends or a signal comes."""
    from swarmpose.messages.schema import keys
    from swarmpose.pipeline.service import build_worker

    config = settings_of(args)
    with ExitStack() as stack:
        worker, _, _ = build_worker(config, stack, replay=False)
        stop_on_signals(worker.stop, stack)
        z = config.zenoh
        where = f"zenoh {z.zenoh_mode}" + (f", connect {', '.join(z.connect)}" if z.connect else "") + (
            f", listen {', '.join(z.listen)}" if z.listen else "")
        print(f"swarmpose serve: {config.source} -> {', '.join(keys(config.camera_id).values())} ({where}); "
              "Ctrl-C stops", file=sys.stderr)
        worker.run()
    return 1 if worker.state in ("source-failed", "failed") else 0


def cmd_replay(args: argparse.Namespace) -> int:
    """Track a recording frame by frame into files; Δ and A(t) when it has ground truth."""
    from swarmpose.pipeline.service import build_worker, format_summary, run_summary

    config = settings_of(args, REPLAY_DEFAULTS)
    with ExitStack() as stack:
        worker, parts, _ = build_worker(config, stack, replay=True, out=args.out, progress=not quiet(args))
        stop_on_signals(worker.stop, stack)
        started = time.monotonic()
        stats = worker.run()
    result = run_summary(parts, stats, time.monotonic() - started, worker)
    print(json.dumps(result) if args.json else format_summary(result))
    return replay_status(worker)


def replay_status(worker: Worker) -> int:
    """The exit status of a replay: 1 when the source or the worker failed, 130 when a signal
    stopped it, 1 when a sink failed (what the others wrote stays), else 0."""
    if worker.state in ("source-failed", "failed"):
        return 1
    if worker.state == "stopping":
        print(f"swarmpose replay: {INTERRUPTED_NOTE}", file=sys.stderr)
        return INTERRUPTED
    return 1 if worker.sink_errors else 0


def cmd_health(args: argparse.Namespace) -> int:
    """Exit 0 when the worker's status file is fresh and it is running, 1 otherwise (docker HEALTHCHECK)."""
    try:
        path = args.file or load(ServiceConfig, {}).health_file
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
        if not Path(path).parent.is_dir():
            print(f"unhealthy: {path}: its folder does not exist; give the worker's --health-file "
                  "(SWARMPOSE_HEALTH_FILE) to both")
        else:
            print(f"unhealthy: no status in {path} yet (no worker writes it, or it has not run a status period: "
                  "check the worker's --health-file)")
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


def _service_parser(sub: argparse._SubParsersAction, common: argparse.ArgumentParser, name: str, text: str,
                    defaults: dict | None = None, only: tuple[str, ...] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(name, parents=[common], formatter_class=DEFAULTS, help=text)
    add_source_argument(p)
    add_flags(p, ServiceConfig, only, defaults=defaults)
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")
    return p


def add_service_commands(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``serve``, ``replay`` and ``health``."""
    p = _service_parser(sub, common, "serve", "track a camera or recording and publish over zenoh (long-running)",
                        only=SERVE_SETTINGS)
    p.set_defaults(func=cmd_serve)

    p = _service_parser(sub, common, "replay", "track a recording into poses.jsonl/csv/bvh + overlay.mp4 (Δ, A(t) "
                                               "with ground truth)", REPLAY_DEFAULTS, REPLAY_SETTINGS)
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("health", parents=[common], formatter_class=DEFAULTS,
                       help="exit 0 if the worker's status file is fresh and it runs (docker HEALTHCHECK)")
    p.add_argument("--file", default=None, help="the status file (default $SWARMPOSE_HEALTH_FILE)")
    p.add_argument("--max-age", type=seconds, default=15.0, help="seconds after which a status counts as stale")
    p.set_defaults(func=cmd_health)
