"""``swarmpose personalize SOURCE --out me.glb``: the person's body shape from ordinary motion.

Tracks the first ``--frames`` frames with the shape space's start body, fits the shape
(:mod:`swarmpose.personalise.personalise`), writes the full-resolution skinned GLB (``--body
me.glb`` loads it; the parameters are kept in its extras) and prints the parameters, the height
and the volume. Every tracker flag applies to the tracking and the pose refits.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from swarmpose.cli.common import DEFAULTS, non_negative_int, positive_int, quiet
from swarmpose.cli.settings import add_flags, advanced
from swarmpose.cli.track import TRACK_SETTINGS, add_source_argument, settings_of
from swarmpose.core.errors import ConfigError
from swarmpose.personalise.fit_settings import FitSettings
from swarmpose.pipeline.config import ServiceConfig


def cmd_personalize(args: argparse.Namespace) -> int:
    """Estimate the shape, write the GLB, print what was found."""
    from swarmpose.body.gltf_write import save_glb
    from swarmpose.personalise.personalise import body_measures
    from swarmpose.pipeline.personalise_run import personalise

    config = settings_of(args)
    out = Path(args.out)
    if out.suffix.lower() not in (".glb", ".gltf"):
        raise ConfigError(f"--out {args.out}: the body is written as glTF; name a .glb (or .gltf) file")
    if not out.parent.exists():
        raise ConfigError(f"--out {args.out}: folder {out.parent} does not exist")
    settings = replace(FitSettings(), keyframes=args.keyframes, rounds=args.rounds, seed=config.tracker.seed,
                       own_pose_rounds=args.own_pose_rounds, own_pose_candidates=args.own_pose_candidates)
    result = personalise(config, args.frames, settings, show_progress=not quiet(args))
    fit = result.fit
    measures = body_measures(fit.body)
    summary = {"body": result.space.body_spec(), "shape": result.space.shape_spec(fit.x),
               "parameters": fit.parameters, **measures,
               "stature_measured_m": None if fit.stature_m is None else round(fit.stature_m, 4),
               "stature_frames": fit.stature_frames, "frames_read": result.frames_read,
               "frames_tracked": len(result.samples), "keyframes": len(fit.keyframes),
               "own_pose_shapes_judged": fit.judged,
               "seconds": round(fit.seconds, 1), "source": config.source, "detector": config.detector}
    body = replace(fit.body, name=f"personalised:{out.stem}",
                   metadata={**fit.body.metadata, "personalised": summary})
    summary["out"] = str(save_glb(body, out))
    if args.json:
        print(json.dumps(summary))
    else:
        params = ", ".join(f"{k} {v:.3f}" for k, v in fit.parameters.items())
        print(f"{config.source}: {summary['frames_tracked']} of {summary['frames_read']} frames tracked, "
              f"{summary['keyframes']} key frames, {summary['seconds']} s")
        print(f"  {result.space.kind} parameters: {params}")
        print(f"  height {measures['height_m']:.3f} m, volume {measures['volume_l']:.1f} l"
              + ("" if fit.stature_m is None else
                 f" (stature measured on the depth: {fit.stature_m:.3f} m over {fit.stature_frames} upright frames)"))
        print(f"  wrote {summary['out']} (use it with --body {summary['out']})")
    return 0


def add_personalize_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``personalize``."""
    p = sub.add_parser("personalize", aliases=["personalise"], parents=[common], formatter_class=DEFAULTS,
                       help="estimate the person's body shape from a recording and write it as GLB")
    add_source_argument(p)
    ignored = ("frames", "overlay", "personalize", "max_people", "retire_frames",  # one person, fitted here
               "coordinates", "floor", "ros_bag", "ros_depth")
    add_flags(p, ServiceConfig, tuple(s for s in TRACK_SETTINGS if s not in ignored))
    p.add_argument("--frames", type=positive_int, default=60, help="frames to read from the start of the source")
    advanced(p.add_argument("--keyframes", type=positive_int, default=FitSettings.keyframes,
                            help="well-spread frames the shape is fitted on"))
    advanced(p.add_argument("--rounds", type=positive_int, default=FitSettings.rounds,
                            help="rounds of shape step then pose step"))
    advanced(p.add_argument("--own-pose-rounds", type=non_negative_int, default=FitSettings.own_pose_rounds,
                            help="the last stage (MakeHuman bodies): polish rounds that give each candidate shape "
                                 "its own poses (0: no last stage)"))
    advanced(p.add_argument("--own-pose-candidates", type=non_negative_int, default=FitSettings.own_pose_candidates,
                            help="the last stage: about this many candidate shapes judged (0: no last stage)"))
    p.add_argument("--out", required=True, help="the personalised body, .glb")
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_personalize)
