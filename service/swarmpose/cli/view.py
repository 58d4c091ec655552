"""``swarmpose view``: a run's recording (or a sequence folder) in the rerun 3D viewer.

``swarmpose view OUT --source SEQ`` shows ``OUT/poses.jsonl`` (written by ``replay``,
``track --out`` or ``serve --record``) over the depth and colour of the source it was
tracked from; ``swarmpose view SEQ`` a sequence folder alone. ``--rrd FILE`` writes the
recording to FILE and opens no viewer; otherwise a viewer opens as ``--view`` does (spawned
where there is a display; served on ``--view-port`` where there is none, until Ctrl-C; or
streamed to ``--view-url``). See :mod:`swarmpose.publish.rerun_files`.
"""

from __future__ import annotations

import argparse
import sys
import threading
from contextlib import ExitStack

from swarmpose.cli.common import DEFAULTS, stop_on_signals
from swarmpose.cli.settings import add_flags, from_args
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.publish.rerun_view import DEPTH_STEP

VIEW_SETTINGS = ("source", "camera_id", "view_url", "view_port", "rrd")


def served(config: ServiceConfig) -> bool:
    """Whether the view is served from this process (no ``--rrd``, no ``--view-url``, no display)."""
    from swarmpose.publish.rerun_stream import has_display

    return not config.rrd and not config.view_url and not has_display()


def wait_for_signal() -> None:
    """Block until SIGINT or SIGTERM (the previous handlers are put back)."""
    stop = threading.Event()
    with ExitStack() as stack:
        stop_on_signals(stop.set, stack)
        while not stop.wait(0.5):
            pass


def cmd_view(args: argparse.Namespace) -> int:
    """Log the recording into a .rrd file or a viewer."""
    from swarmpose.publish.rerun_files import log_recording, poses_file
    from swarmpose.publish.rerun_view import open_view_sink

    config = from_args(ServiceConfig, args)
    poses_file(args.recording)  # a recording that is not there is named before a viewer is started
    sink = open_view_sink(config.camera_id, rrd=config.rrd, view=not config.rrd, url=config.view_url,
                          port=config.view_port, depth_step=args.depth_step)
    try:
        frames = log_recording(sink, args.recording, config.source, config.camera_id)
        where = "; ".join(sink.stream.targets)
        print(f"swarmpose view: {frames} frames of {args.recording} -> {where}")
        if served(config):
            print("swarmpose view: serving until Ctrl-C (SIGINT or SIGTERM)", file=sys.stderr)
            wait_for_signal()
    finally:
        sink.close()
    return 0


def add_view_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``view``."""
    p = sub.add_parser("view", parents=[common], formatter_class=DEFAULTS,
                       help="show a run's poses.jsonl (over its source's depth and colour) or a sequence folder in "
                            "the rerun 3D viewer, or write it to a .rrd file")
    p.add_argument("recording", metavar="RECORDING",
                   help="a folder written by replay/track --out (poses.jsonl), that file, or a sequence folder")
    add_flags(p, ServiceConfig, VIEW_SETTINGS)
    p.add_argument("--depth-step", type=int, default=DEPTH_STEP,
                   help="every how many pixels (rows and columns) the depth point cloud takes")
    p.set_defaults(func=cmd_view)
