"""The ``swarmpose`` command line: one entry point, one subcommand per job.

Errors raised on purpose (:class:`swarmpose.errors.SwarmposeError`) print one line on
stderr and exit with status 2; argparse reports bad flags the same way.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import __version__
from .errors import SwarmposeError

DEMO_DIR = Path("demo-output")


def _add_body_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--body", default="builtin",
                   help="'builtin' (default), 'makehuman:DIR' (MakeHuman assets directory) or a .glb/.gltf file")
    p.add_argument("--shape", default=None,
                   help="shape preset: builtin presets (default, male, female, male-heavy, ...) or "
                        "'height=1.8,torso=1.1,arms=1,legs=1'; MakeHuman presets (male, female, male-heavy, "
                        "female-slim, male-tall, female-short, ...)")


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def resolve_motion(spec: str, body, frames: int, fps: float):
    """``builtin:NAME`` -> a procedural motion; anything else is a BVH file retargeted onto ``body``."""
    if spec.startswith("builtin:"):
        from .builtin_motions import builtin_motion
        return builtin_motion(spec.split(":", 1)[1], frames, fps)
    from .mocap import load_motion
    return load_motion(str(Path(spec).expanduser()), body, fps)


def cmd_synth(args: argparse.Namespace) -> int:
    """Render a synthetic RGBD sequence with ground truth."""
    from .model.loader import load_body
    from .synth import SynthConfig, synthesize

    config = SynthConfig(frames=args.frames, fps=args.fps, seed=args.seed, camera_distance=args.camera_distance,
                         camera_yaw_deg=args.camera_yaw, camera_height=args.camera_height,
                         layout=args.layout, skinning=args.skinning)
    config.validate()
    body = load_body(args.body, args.shape)
    motion = resolve_motion(args.motion, body, args.frames, args.fps)
    summary = synthesize(body, motion, Path(args.out), config,
                         description={"shape": args.shape, "motion_spec": args.motion}, progress=not args.quiet)
    _print_summary(summary, body)
    return 0


def _print_summary(summary: dict, body) -> None:
    depth = summary["person_depth_m"]
    print(f"wrote {summary['frames']} frames of {summary['motion']} on {summary['body']} "
          f"(height {body.height:.2f} m) to {summary['out']}")
    print("  color/*.png depth/*.png (uint16 mm) intrinsic.json groundtruth.jsonl sequence.json")
    if depth:
        print(f"  person depth range: {depth[0]:.2f}..{depth[1]:.2f} m")


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job on embedded defaults: synthesise a short sequence, serve it over zenoh with a
    subscriber beside it, report Δ, A(t), fps, latency and the replay outputs."""
    from .builtin_motions import builtin_motion
    from .demo import run_demo
    from .model.loader import load_body
    from .synth import SynthConfig, synthesize

    body = load_body("builtin", "default")
    config = SynthConfig(frames=args.frames, fps=30.0, seed=0)
    motion = builtin_motion("wave", config.frames, config.fps)
    out = Path(args.out)
    summary = synthesize(body, motion, out, config, description={"motion_spec": "builtin:wave"},
                         progress=not args.quiet)
    _print_summary(summary, body)
    print(f"tracking it with the service (hybrid objective, simulated 2D joints, {args.particles} particles x "
          f"{args.generations} generations per frame) ...")
    return run_demo(out, out.parent / "replay", args.particles, args.generations, args.quiet, args.frames)


def cmd_body(args: argparse.Namespace) -> int:
    """Describe a body model, optionally exporting it (personalised) to GLB."""
    from .model.loader import load_body

    body = load_body(args.body, args.shape)
    if args.lod:
        body = body.tracking_lod(args.lod)
    info = {"name": body.name, "height_m": round(body.height, 4), "vertices": len(body.vertices),
            "triangles": len(body.triangles), "bones": len(body.bone_names)}
    if args.export:
        from .model.gltf import save_glb
        info["exported"] = str(save_glb(body, Path(args.export)))
    print(json.dumps(info) if args.json else "\n".join(f"{k}: {v}" for k, v in info.items()))
    return 0


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 64x64, got {text!r}") from None
    if not (8 <= w <= 512 and 8 <= h <= 512):
        raise argparse.ArgumentTypeError(f"tile sides must be within 8..512, got {text!r}")
    return w, h


def cmd_bench_score(args: argparse.Namespace) -> int:
    """Hypotheses per second of the OpenCL scorer against the Open3D ray-casting baseline."""
    from .bench import bench_score, format_bench

    result = bench_score(particles=args.particles, resolution=args.resolution, body=args.body, shape=args.shape,
                         repeats=args.repeats, device=args.device, lod=args.triangles)
    print(json.dumps(result) if args.json else format_bench(result))
    return 0


def cmd_bench_detect(args: argparse.Namespace) -> int:
    """Time per frame and COCO-photo error of the ONNX 2D detectors."""
    from .bench_detect import bench_detectors, format_detect_bench

    result = bench_detectors(repeats=args.repeats, assets=args.assets, threads=args.threads)
    print(json.dumps(result) if args.json else format_detect_bench(result))
    return 0


def cmd_probe(args: argparse.Namespace) -> int:
    """Read a few frames of a source and describe them (resolution, intrinsics, depth, rate, joints)."""
    from .probe import run_probe

    return run_probe(args.source, frames=args.frames, joints=args.joints, as_json=args.json)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(prog="swarmpose", description="markerless 3D human pose tracking for RGBD cameras")
    parser.add_argument("--version", action="version", version=f"swarmpose {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("synth", help="render a synthetic RGBD sequence with ground truth from a body and a motion")
    _add_body_options(p)
    p.add_argument("--motion", required=True, help="a BVH file (CMU, Mixamo or MakeHuman skeleton) or builtin:NAME "
                                                   "(wave, squat, walk, turn, jumping_jacks)")
    p.add_argument("--frames", type=_positive_int, required=True, help="number of frames to write")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--seed", type=int, default=0, help="seed of the depth noise and the simulated detector")
    p.add_argument("--fps", type=float, default=30.0, help="camera frame rate; the motion is resampled to it")
    p.add_argument("--camera-distance", type=float, default=3.0, help="metres from the subject's start (0.5..8)")
    p.add_argument("--camera-yaw", type=float, default=0.0, help="degrees around the subject, 0 = in front")
    p.add_argument("--camera-height", type=float, default=1.2, help="lens height above the floor, metres")
    p.add_argument("--skinning", choices=("dqs", "lbs"), default="dqs", help="skinning of the rendered body")
    p.add_argument("--layout", default="coco17", help="keypoint layout of the simulated detector")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("demo", help="the main job on built-in defaults (needs no files)")
    p.add_argument("--out", default=str(DEMO_DIR / "sequence"), help="where the demo writes its sequence")
    p.add_argument("--frames", type=_positive_int, default=30)
    p.add_argument("--particles", type=_positive_int, default=64, help="PSO particles per generation")
    p.add_argument("--generations", type=_positive_int, default=64, help="PSO generations per frame")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_demo)

    bench = sub.add_parser("bench", help="benchmarks").add_subparsers(dest="bench", required=True)
    p = bench.add_parser("score", help="OpenCL scorer vs the Open3D ray-casting baseline, hypotheses per second")
    _add_body_options(p)
    p.add_argument("--particles", type=_positive_int, default=64, help="hypotheses per generation")
    p.add_argument("--resolution", type=_resolution, default=(64, 64), help="depth tile WxH over the person's box")
    p.add_argument("--triangles", type=_positive_int, default=1500, help="tracking level of detail, triangles")
    p.add_argument("--repeats", type=_positive_int, default=20, help="timed generations (medians)")
    p.add_argument("--device", default=None, help="OpenCL device: cpu, gpu, P:D or part of its name "
                                                  "(default: $SWARMPOSE_CL_DEVICE, else a GPU, else PoCL)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_score)
    p = bench.add_parser("detect", help="ONNX 2D detectors: time per frame and error on a COCO photo")
    p.add_argument("--repeats", type=_positive_int, default=20, help="timed runs per detector and image (medians)")
    p.add_argument("--threads", type=_positive_int, default=None, help="onnxruntime threads (default: half the cores)")
    p.add_argument("--assets", default=None,
                   help="shared assets folder (default: $SWARMPOSE_ASSETS or ../shared/assets)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_detect)

    p = sub.add_parser("probe", help="read a few frames of a source: resolution, intrinsics, depth range, rate, joints")
    p.add_argument("--source", required=True, help="folder:DIR, rgbd:C.png,D.png,K.json, mkv:FILE, bag:FILE, "
                                                   "realsense:[SERIAL], azure:[INDEX], openni2:[FILE.oni|URI]")
    p.add_argument("--joints", default=None, help="also detect 2D joints: simulated, onnx:MODEL, openpose-json:DIR")
    p.add_argument("--frames", type=_positive_int, default=10, help="frames to read (default 10)")
    p.add_argument("--json", action="store_true", help="one JSON object per frame, then a summary object")
    p.set_defaults(func=cmd_probe)

    from .cli_track import add_track_commands

    add_track_commands(sub, _add_body_options, _positive_int, _resolution)

    from .cli_serve import add_service_commands

    add_service_commands(sub)

    p = sub.add_parser("body", help="describe a body model; --export writes it as GLB")
    _add_body_options(p)
    p.add_argument("--lod", type=int, default=0, help="decimate to about this many triangles (at least 100)")
    p.add_argument("--export", default=None, help="write the (personalised) body to this .glb")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_body)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SwarmposeError as exc:
        print(f"swarmpose: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("swarmpose: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
