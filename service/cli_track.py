"""``swarmpose track`` and ``swarmpose eval``: the tracker over a sequence, and its Δ / A(t)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .errors import ConfigError


def add_track_options(p: argparse.ArgumentParser, add_body_options, positive_int, resolution) -> None:
    """The options ``track`` and ``eval`` share."""
    p.add_argument("seq", metavar="SEQ", help="a sequence folder (from `swarmpose synth`) or a --source URI "
                                              "(folder:DIR, bag:FILE, mkv:FILE, openni2:FILE.oni, ...)")
    add_body_options(p)
    p.add_argument("--mode", choices=("hybrid", "depth", "joints", "lift"), default="hybrid",
                   help="objective: hybrid (w_D=3, w_J=1), depth (w_J=0), joints (w_D=0), lift (J^e, no model)")
    p.add_argument("--joints", default="simulated",
                   help="2D joints: simulated | onnx:MODEL.onnx | openpose-json:DIR (default simulated)")
    p.add_argument("--particles", type=positive_int, default=64, help="PSO particles per generation")
    p.add_argument("--generations", type=positive_int, default=64, help="PSO generations per frame")
    p.add_argument("--pso", choices=("perturbed", "canonical"), default="perturbed", help="PSO variant")
    p.add_argument("--depth-weight", type=float, default=None, help="w_D (default: the mode's)")
    p.add_argument("--joints-weight", type=float, default=None, help="w_J (default: the mode's)")
    p.add_argument("--tile", type=resolution, default=(64, 64), help="depth tile WxH over the person's box")
    p.add_argument("--triangles", type=positive_int, default=1500, help="tracking level of detail")
    p.add_argument("--smoothing", type=float, default=0.0, help="blend each pose with the previous (0..1, 0 = off)")
    p.add_argument("--seed", type=int, default=0, help="PSO seed")
    p.add_argument("--device", default=None, help="OpenCL device (default: $SWARMPOSE_CL_DEVICE, a GPU, else PoCL)")
    p.add_argument("--frames", type=positive_int, default=None, help="stop after this many frames")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def _tracker_config(args: argparse.Namespace):
    from .pso import PsoConfig
    from .tracker import TrackerConfig

    return TrackerConfig(mode=args.mode, pso=PsoConfig(particles=args.particles, generations=args.generations,
                                                       variant=args.pso),
                         depth_weight=args.depth_weight, joints_weight=args.joints_weight, tile=tuple(args.tile),
                         triangles=args.triangles, seed=args.seed, smoothing=args.smoothing, device=args.device)


def run_from_args(args: argparse.Namespace, out: Path | None):
    """Open the source and detector, track, return (run, source)."""
    from .joints2d.registry import make_detector
    from .model.loader import load_body
    from .sources.registry import open_source
    from .track_run import track_source
    from .tracker import Tracker

    config = _tracker_config(args)
    body = load_body(args.body, args.shape)
    source = open_source(args.seq)
    try:
        detector = make_detector(args.joints, source)
        try:
            run = track_source(source, detector, lambda intr: Tracker(body, intr, config), out=out,
                               max_frames=args.frames, progress=not args.quiet)
        finally:
            detector.close()
    finally:
        source.close()
    return run, source


def cmd_track(args: argparse.Namespace) -> int:
    """Track a sequence; one JSON line per frame in --out."""
    run, _ = run_from_args(args, Path(args.out))
    states = ", ".join(f"{k} {v}" for k, v in sorted(run.states.items()))
    print(f"tracked {run.frames} frames ({states}) at {run.fps:.2f} frames/s; poses in {args.out}")
    return 0


def evaluate_run(run, ground_truth) -> dict:
    """Δ, A(t) and coverage of a run against a sequence's ground truth, over the frames the run
    went through (a frame it skipped or could not estimate counts as a miss)."""
    from .evaluate import summarise_frames

    recorded = {r["frame"] for r in run.records}
    return summarise_frames(ground_truth, [f for f in ground_truth.frames if f in recorded], run.estimates)


def cmd_eval(args: argparse.Namespace) -> int:
    """Track a synthetic sequence and report Δ and A(t) against its ground truth."""
    from .evaluate import plot_accuracy
    from .model.skeleton import EVAL_JOINTS

    run, source = run_from_args(args, Path(args.out) if args.out else None)
    gt = getattr(source, "ground_truth", None)
    if gt is None:
        raise ConfigError(f"{args.seq} has no groundtruth.jsonl; eval needs a sequence from `swarmpose synth`")
    summary = evaluate_run(run, gt)
    result = {"mpjpe_mm": summary["mpjpe_mm"], "A": {str(t): a for t, a in summary["A"].items()},
              "fps": run.fps, "frames": run.frames, "mode": args.mode, "coverage": summary["coverage"],
              "states": run.states, "joints": args.joints, "body": args.body, "shape": args.shape,
              "particles": args.particles, "generations": args.generations, "pso": args.pso,
              "depth_weight": args.depth_weight, "joints_weight": args.joints_weight, "seed": args.seed,
              "per_joint_mm": dict(zip(EVAL_JOINTS, summary["per_joint_mm"]))}
    if args.plot:
        plot_accuracy({f"{args.mode}": summary["A"]}, args.plot, title=str(args.seq))
        result["plot"] = args.plot
    if args.json:
        print(json.dumps(result))
    else:
        delta = "n/a" if summary["mpjpe_mm"] is None else f"{summary['mpjpe_mm']:.1f} mm"
        print(f"{args.seq}: mode {args.mode}, {run.frames} frames, Δ = {delta}, coverage {summary['coverage']:.0%}, "
              f"{run.fps:.2f} frames/s")
        print("  A(t): " + "  ".join(f"{t}mm {100 * a:.0f}%" for t, a in summary["A"].items()))
    return 0


def add_track_commands(sub, add_body_options, positive_int, resolution) -> None:
    """Register ``track`` and ``eval`` on the CLI's subparsers."""
    p = sub.add_parser("track", help="track a sequence or recording: one JSON line per frame")
    add_track_options(p, add_body_options, positive_int, resolution)
    p.add_argument("--out", required=True, help="poses.jsonl to write (flushed per frame)")
    p.set_defaults(func=cmd_track)

    p = sub.add_parser("eval", help="track a synthetic sequence and report Δ and A(t) against its ground truth")
    add_track_options(p, add_body_options, positive_int, resolution)
    p.add_argument("--out", default=None, help="also write the poses as JSON lines")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.add_argument("--plot", default=None, help="draw A(t) into this PNG")
    p.set_defaults(func=cmd_eval)
