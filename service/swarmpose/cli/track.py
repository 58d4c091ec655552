"""``swarmpose track`` and ``swarmpose eval``: the tracker over a sequence, and its Δ / A(t).

Both run the sequential pipeline (:mod:`swarmpose.pipeline.run`): one thread, every frame.
``--out DIR`` gets the same files as ``replay`` (``poses.jsonl`` of frame messages,
``poses.csv``, ``poses.bvh``, ``overlay.mp4`` unless ``--no-overlay``, the ROS 2 bag ``poses_ros2/``
unless ``--no-ros-bag``). Exit status 1 when
an output file could not be written or the source broke off (a truncated recording, a camera
that vanished: a warning names it); what was tracked until then is written and reported.
SIGINT or SIGTERM ends the run after the frame in progress, every file closed (exit status 130).
``eval`` refuses a source without ground truth at once (exit status 2).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from contextlib import ExitStack
from typing import TYPE_CHECKING

from swarmpose.cli.common import DEFAULTS, INTERRUPTED, INTERRUPTED_NOTE, quiet, stop_on_signals
from swarmpose.cli.settings import add_flags, from_args
from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import leaves
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.tracking.config import TrackerConfig

if TYPE_CHECKING:  # what runs the commands is imported by them (the parser needs none of it)
    from swarmpose.pipeline.run import RunSummary
    from swarmpose.pipeline.service import Parts

TRACK_SETTINGS = ("source", "detector", "models", "body", "shape", *leaves(TrackerConfig), "camera_id", "frames",
                  "overlay", "ros_bag", "ros_depth", "coordinates", "floor", "view", "view_url", "view_port", "rrd")
"""The settings ``track`` and ``eval`` take (``serve`` and ``replay`` take these and the service's)."""


def add_source_argument(p: argparse.ArgumentParser) -> None:
    """The optional positional SEQ: the same as ``--source``."""
    p.add_argument("seq", metavar="SEQ", nargs="?", default=None,
                   help="the frame source, as --source (a sequence folder or any source URI)")


def settings_of(args: argparse.Namespace, defaults: dict | None = None) -> ServiceConfig:
    """The settings of a command's flags (SEQ stands for --source) over the other layers."""
    if args.seq is not None:
        if args.source is not None and args.source != args.seq:
            raise ConfigError(f"two sources: SEQ {args.seq!r} and --source {args.source!r}; give one")
        args.source = args.seq
    return from_args(ServiceConfig, args, defaults)


def run_tracking(args: argparse.Namespace, *, score: bool) -> tuple[ServiceConfig, Parts, RunSummary]:
    """Open the parts of the command's settings, track every frame into ``--out``."""
    from swarmpose.pipeline.run import run_sequence
    from swarmpose.pipeline.service import open_parts

    config = settings_of(args)
    stop = threading.Event()
    with ExitStack() as stack:
        parts = open_parts(config, stack, out=args.out or "", score=score, need_ground_truth=score)
        if threading.current_thread() is threading.main_thread():  # SIGINT/SIGTERM: end after this frame
            stop_on_signals(stop.set, stack)
        summary = run_sequence(parts.source, parts.pipeline, parts.sinks, camera=config.camera_id,
                               frames=config.frames, progress=not quiet(args), stop=stop, label=args.command)
    if summary.interrupted:
        print(f"swarmpose: {INTERRUPTED_NOTE}", file=sys.stderr)
    world = parts.pipeline.world
    if config.coordinates == "world" and (world is None or world.state is None
                                          or world.state.camera_to_world is None):
        print("swarmpose: --coordinates world: no floor was found (or nobody was tracked on it), so the poses "
              "stayed in the camera frame (their messages say coordinates camera); pass --floor EXTRINSICS.json",
              file=sys.stderr)
    return config, parts, summary


def nothing_read(run: RunSummary) -> bool:
    """Whether the run read frames and could decode none of them (each skipped)."""
    return run.frames > 0 and run.states.get("skipped", 0) == run.frames


def exit_status(run: RunSummary) -> int:
    """130 when a signal stopped the run, 1 when a sink or the source failed or no frame could be
    read (said on stderr), else 0."""
    if run.interrupted:
        return INTERRUPTED
    if nothing_read(run):
        print(f"swarmpose: none of the {run.frames} frames could be read (each was skipped; the warnings say "
              "why): the outputs hold no pose; check the recording's files", file=sys.stderr)
        return 1
    return 1 if run.sink_errors or run.source_error else 0


def cmd_track(args: argparse.Namespace) -> int:
    """Track a sequence; the frame messages and files in --out."""
    _, parts, run = run_tracking(args, score=False)
    states = ", ".join(f"{k} {v}" for k, v in sorted(run.states.items()))
    print(f"tracked {run.frames} frames ({states}) at {run.fps:.2f} frames/s; poses in {args.out}/poses.jsonl")
    return exit_status(run)


def cmd_eval(args: argparse.Namespace) -> int:
    """Track a synthetic sequence and report Δ and A(t) against its ground truth."""
    from swarmpose.body.skeleton import EVAL_JOINTS
    from swarmpose.pipeline.service import format_accuracy, score_summary

    config, parts, run = run_tracking(args, score=True)
    accuracy = score_summary(parts) or {"mpjpe_mm": None, "coverage": 0.0, "A": {}, "per_joint_mm": []}
    t = config.tracker
    result = {**{k: accuracy[k] for k in ("mpjpe_mm", "A", "coverage")}, "fps": run.fps, "frames": run.frames,
              "states": run.states, "mode": t.mode, "detector": parts.config.detector, "body": config.body,
              "shape": config.shape, "particles": t.particles, "generations": t.generations, "pso": t.pso,
              "depth_weight": t.depth_weight, "joints_weight": t.joints_weight, "seed": t.seed,
              "per_joint_mm": dict(zip(EVAL_JOINTS, accuracy["per_joint_mm"])), "source_error": run.source_error,
              "sink_errors": run.sink_errors, "max_people": t.max_people}
    if "people" in accuracy:
        result["people"] = accuracy["people"]
    if args.plot:
        from swarmpose.sim.evaluate import plot_accuracy

        plot_accuracy({t.mode: {int(k): v for k, v in accuracy["A"].items()}}, args.plot, title=config.source)
        result["plot"] = args.plot
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{config.source}: mode {t.mode}, {run.frames} frames at {run.fps:.2f} frames/s")
        print("\n".join("  " + line for line in format_accuracy(accuracy)))
    return exit_status(run)


def add_track_commands(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``track`` and ``eval``."""
    p = sub.add_parser("track", parents=[common], formatter_class=DEFAULTS,
                       help="track a sequence or recording into poses.jsonl/csv/bvh (+ overlay.mp4)")
    add_source_argument(p)
    add_flags(p, ServiceConfig, TRACK_SETTINGS)
    p.add_argument("--out", required=True, help="output folder (created): poses.jsonl, poses.csv, poses.bvh, "
                                                "overlay.mp4")
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")
    p.set_defaults(func=cmd_track)

    p = sub.add_parser("eval", parents=[common], formatter_class=DEFAULTS,
                       help="track a synthetic sequence and report Δ and A(t) against its ground truth")
    add_source_argument(p)
    add_flags(p, ServiceConfig, TRACK_SETTINGS)
    p.add_argument("--out", default=None, help="also write the files of `track` into this folder")
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.add_argument("--plot", default=None, help="draw A(t) into this PNG")
    p.set_defaults(func=cmd_eval)
