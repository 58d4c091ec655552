"""``swarmpose bench score|track|live|detect|accuracy|utdmhad|still|overlays``: the benchmarks BENCHMARKS.md
records."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from swarmpose.bench.hard_motions import HARD_MOTIONS
from swarmpose.bench.matrix import DETECTORS, MODES, MOTIONS, SUBSETS
from swarmpose.bench.still_plan import StillPlan
from swarmpose.bench.store import BENCH_SETTINGS
from swarmpose.bench.utdmhad_names import ACTIONS, SHAPES, SUBJECTS
from swarmpose.cli.common import DEFAULTS, add_body_options, non_negative_float, positive_int, quiet
from swarmpose.cli.settings import add_flags, from_args
from swarmpose.cli.track import TRACK_SETTINGS, add_source_argument, settings_of
from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import parse_size
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.sources.utdmhad_sync import DEPTH_LAG_FRAMES
from swarmpose.tracking.config import TrackerConfig

LIVE_SETTINGS = (*(s for s in TRACK_SETTINGS if s not in ("frames", "overlay", "ros_bag", "ros_depth", "view",
                                                          "view_url", "view_port", "rrd")),
                 "rate", "frame_budget_ms")
"""The settings ``bench live`` takes: a served run's, without the outputs it does not write."""
OVERLAY_SETTINGS = ("particles", "generations", "max_people")
"""The tracker settings ``bench overlays`` takes."""


def _size(text: str) -> tuple[int, int]:
    try:
        return parse_size(text, "tile")
    except ConfigError as exc:  # say it argparse's way (usage line, exit 2)
        raise argparse.ArgumentTypeError(str(exc)) from None


def cmd_bench_score(args: argparse.Namespace) -> int:
    """Hypotheses per second of the OpenCL scorer against the Open3D ray-casting baseline."""
    from swarmpose.bench.score import bench_score, format_bench

    result = bench_score(particles=args.particles, resolution=args.tile, body=args.body, shape=args.shape,
                         repeats=args.repeats, device=args.device, lod=args.triangles, host_fk=args.host_fk)
    print(json.dumps(result) if args.json else format_bench(result))
    return 0


def cmd_bench_track(args: argparse.Namespace) -> int:
    """End-to-end frames per second of the tracker on a fixed synthetic sequence, with the split."""
    from swarmpose.bench.track import bench_track, format_track_bench

    result = bench_track(body=args.body, shape=args.shape, motion=args.motion, frames=args.frames,
                         repeats=args.repeats, tracker=from_args(TrackerConfig, args), progress=not quiet(args))
    print(json.dumps(result) if args.json else format_track_bench(result))
    return 0


def cmd_bench_live(args: argparse.Namespace) -> int:
    """What a client sees when a recording is served live: poses/s, latency, start-up, live and client Δ."""
    from swarmpose.bench.live import bench_live, format_live_bench

    result = bench_live(settings_of(args), seconds=args.seconds, offline=args.offline, startup=args.startup)
    print(json.dumps(result) if args.json else format_live_bench(result))
    return 0


def cmd_bench_detect(args: argparse.Namespace) -> int:
    """Time per frame and COCO-photo error of the ONNX 2D detectors."""
    from swarmpose.bench.detect import bench_detectors, format_detect_bench

    result = bench_detectors(repeats=args.repeats, assets=args.assets, threads=args.threads)
    print(json.dumps(result) if args.json else format_detect_bench(result))
    return 0


def _names(allowed: tuple[str, ...] | None = None):
    """An argparse type: comma-separated names out of ``allowed`` (None: any names)."""
    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        bad = [n for n in names if allowed is not None and n not in allowed]
        if bad or not names:
            hint = f"choose from {', '.join(allowed)}" if allowed is not None else "give names, e.g. male,female"
            raise argparse.ArgumentTypeError(f"{text!r}: {hint} (comma-separated)")
        return names
    return parse


def cmd_bench_accuracy(args: argparse.Namespace) -> int:
    """The tracker over the benchmark matrix: per cell and mode Δ, A(100), lost frames, facing."""
    from swarmpose.bench.accuracy import mean_over_seeds, run_matrix
    from swarmpose.bench.accuracy_report import format_goals, format_summary, format_table, plot_heatmap

    tracker = {**_tracker_settings(args), "max_people": args.max_people}
    records = run_matrix(Path(args.out), subset=args.subset, detectors=args.detectors, modes=args.modes,
                         frames=args.frames, tracker=tracker, assets=args.assets, progress=not quiet(args),
                         seeds=args.seeds, motions=args.motions)
    out = Path(args.out)
    merged = mean_over_seeds(records) if args.seeds > 1 else records
    table = "\n\n".join([format_summary(merged), format_table(merged), format_goals(merged)]) + "\n"
    (out / "table.md").write_text(table)
    (out / "records.json").write_text(json.dumps(records, indent=1))
    plot_heatmap(merged, out / "heatmap.png")
    if args.json:
        print(json.dumps({"out": str(out), "records": records}))
    else:
        print(table + f"\nrecords, table.md and heatmap.png in {out}")
    return 0


def cmd_bench_utdmhad(args: argparse.Namespace) -> int:
    """The tracker on UTD-MHAD's real Kinect sequences against the Kinect skeleton."""
    from swarmpose.bench.utdmhad import format_table as format_utdmhad_table
    from swarmpose.bench.utdmhad import run_utdmhad
    from swarmpose.bench.utdmhad import summary as utdmhad_summary

    tracker = _tracker_settings(args, ("auto_height",))
    records = run_utdmhad(Path(args.out), modes=args.modes, detectors=args.detectors, shapes=args.shapes,
                          frames=args.frames, tracker=tracker, subjects=args.subjects,
                          actions=tuple(int(a) for a in args.actions), assets=args.assets,
                          lag_frames=args.lag, progress=not quiet(args), seeds=args.seeds)
    out = Path(args.out)
    overall = utdmhad_summary(records)
    table = format_utdmhad_table(records)
    (out / "table.md").write_text(table)
    (out / "records.json").write_text(json.dumps(records, indent=1))
    if args.json:
        print(json.dumps({"out": str(out), "summary": overall, "records": records}))
    else:
        def mm(value: float | None) -> str:
            return "–" if value is None else f"{value:.1f}"

        lines = [f"{name}: Δ {mm(v['mpjpe_mm'])} mm, with the joint offsets {mm(v['mpjpe_offset_mm'])} mm over "
                 f"{v['sequences']} sequences × {v['seeds']} seeds ({v['frames']} frames, {v['lost']} lost)"
                 for name, v in overall.items()]
        print(table + "\n" + "\n".join(lines) + f"\nrecords and table.md in {out}")
    return 0


def cmd_bench_still(args: argparse.Namespace) -> int:
    """Jitter of a person standing still and the lag when they move: unsmoothed, one-Euro, centred."""
    from swarmpose.bench.still import run_still, summary
    from swarmpose.bench.still_report import format_rows, format_summary

    plan = StillPlan(clip=args.clip, at_s=args.at, hold_s=args.hold, moving_s=args.moving, settle_s=args.settle,
                     body=args.body, shapes=args.shapes, yaws=args.yaws, detectors=args.detectors)
    tracker = _tracker_settings(args, exclude=("smoothing",))
    rows = run_still(Path(args.out), plan, tracker, assets=args.assets, progress=not quiet(args))
    groups = summary(rows)
    out = Path(args.out)
    table = format_summary(groups) + "\n\n" + format_rows(rows) + "\n"
    (out / "table.md").write_text(table)
    (out / "records.json").write_text(json.dumps(rows, indent=1))
    print(json.dumps({"out": str(out), "summary": groups, "rows": rows}) if args.json
          else table + f"\nrecords.json and table.md in {out}")
    return 0


def _floats(text: str) -> tuple[float, ...]:
    """An argparse type: comma-separated numbers."""
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        values = ()
    if not values:
        raise argparse.ArgumentTypeError(f"{text!r}: give comma-separated numbers, e.g. 0,90")
    return values


def cmd_bench_overlays(args: argparse.Namespace) -> int:
    """Overlay pictures of the tracker on the real Kinect frames without ground truth."""
    from swarmpose.bench.qualitative import write_overlays

    config = from_args(TrackerConfig, args)
    settings = {name: getattr(config, name) for name in OVERLAY_SETTINGS}
    report = write_overlays(Path(args.out), detector=args.detector, assets=args.assets, settings=settings)
    print(json.dumps(report) if args.json else "\n".join(
        f"{args.out}/{name}: {', '.join(r['states'])}" for name, r in report.items()))
    return 0


def _add_assets(p: argparse.ArgumentParser) -> None:
    p.add_argument("--assets", default=None,
                   help="shared assets folder (default: $SWARMPOSE_ASSETS or ../shared/assets)")


def _tracker_settings(args: argparse.Namespace, extra: tuple[str, ...] = (), exclude: tuple[str, ...] = ()) -> dict:
    """The values of the tracker settings a benchmark took as flags (:data:`BENCH_SETTINGS` and
    ``extra``, less ``exclude``), over the environment, config file and :class:`TrackerConfig`'s defaults."""
    config = from_args(TrackerConfig, args)
    return {name: getattr(config, name) for name in (*BENCH_SETTINGS, *extra) if name not in exclude}


def add_bench_commands(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``bench score``, ``track``, ``live``, ``detect``, ``accuracy``, ``utdmhad``, ``still`` and
    ``overlays``."""
    bench = sub.add_parser("bench", help="benchmarks").add_subparsers(dest="bench", required=True, metavar="BENCH")
    p = bench.add_parser("score", parents=[common], formatter_class=DEFAULTS,
                         help="OpenCL scorer vs the Open3D ray-casting baseline, hypotheses per second")
    add_body_options(p)
    p.add_argument("--particles", type=positive_int, default=64, help="hypotheses per generation")
    p.add_argument("--tile", "--resolution", dest="tile", type=_size, default=(64, 64),
                   help="depth tile WxH pixels over the person's box")
    p.add_argument("--triangles", type=positive_int, default=1500, help="tracking level of detail, triangles")
    p.add_argument("--repeats", type=positive_int, default=20, help="timed generations (medians)")
    p.add_argument("--device", default="", help="OpenCL device: cpu, gpu, P:D or part of its name (empty: a GPU, "
                                                "else PoCL)")
    p.add_argument("--host-fk", action="store_true",
                   help="forward kinematics in numpy on the host, as before it moved onto the device (for comparison)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_score)
    p = bench.add_parser("track", parents=[common], formatter_class=DEFAULTS,
                         help="the tracker's frames per second on a fixed synthetic sequence, where the time goes")
    add_body_options(p)
    p.add_argument("--motion", default="builtin:walk", help="builtin:NAME or a BVH file, filmed from the front")
    p.add_argument("--frames", type=positive_int, default=30, help="frames of the sequence")
    p.add_argument("--repeats", type=positive_int, default=3, help="runs over the sequence (medians)")
    add_flags(p, TrackerConfig)
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_track)
    p = bench.add_parser("live", parents=[common], formatter_class=DEFAULTS,
                         help="serve a recording at its rate (looped) and report what a client sees: poses/s, "
                              "latency, start-up, live and client Δ")
    add_source_argument(p)
    add_flags(p, ServiceConfig, LIVE_SETTINGS)
    p.add_argument("--seconds", type=non_negative_float, default=20.0,
                   help="how long to serve after the first pose")
    p.add_argument("--offline", action=argparse.BooleanOptionalAction, default=True,
                   help="also track every frame of the sequence for the offline Δ")
    p.add_argument("--startup", action=argparse.BooleanOptionalAction, default=True,
                   help="also time the start-up of two serve processes (empty cache, then warm)")
    p.add_argument("--config", dest="config_file", default=None, help="TOML file of settings ($SWARMPOSE_CONFIG)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_live)
    p = bench.add_parser("detect", parents=[common], formatter_class=DEFAULTS,
                         help="ONNX 2D detectors: time per frame and error on a COCO photo")
    p.add_argument("--repeats", type=positive_int, default=20, help="timed runs per detector and image (medians)")
    p.add_argument("--threads", type=positive_int, default=None, help="onnxruntime threads (default: half the cores)")
    _add_assets(p)
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_detect)
    p = bench.add_parser("accuracy", parents=[common], formatter_class=DEFAULTS,
                         help="the tracker over views x motions x shapes x detectors (resumable)")
    p.add_argument("--out", required=True, help="folder of the sequences, the per-cell results, table and heat map; "
                                                "run again to resume")
    p.add_argument("--subset", choices=SUBSETS, default="full",
                   help="full: 15 sequences x 3 detectors; regression: walk from the side and behind, MoveNet; "
                        "hard: 6 hard motions x 5 views x MoveNet and BlazePose; hard-regression: the turning "
                        "walk from the front, MoveNet")
    p.add_argument("--detectors", type=_names(tuple(DETECTORS)), default=None,
                   help=f"comma-separated subset of {', '.join(DETECTORS)} (default: the subset's)")
    p.add_argument("--motions", type=_names((*MOTIONS, *HARD_MOTIONS)), default=None,
                   help="comma-separated motions of the subset to run (default: all of them)")
    p.add_argument("--modes", type=_names(MODES), default=",".join(MODES), help="comma-separated tracker modes")
    p.add_argument("--frames", type=positive_int, default=40,
                   help="frames per sequence (a hard motion: the first N of its segment, at most all of it)")
    p.add_argument("--max-people", type=positive_int, default=1,
                   help="people tracked per frame (> 1: segmentation and a detection per person)")
    p.add_argument("--seeds", type=positive_int, default=1,
                   help="tracker seeds per cell and mode; the table and heat map show the mean over them "
                        "(a cell's Δ varies between seeds)")
    _add_assets(p)
    add_flags(p, TrackerConfig, BENCH_SETTINGS)
    p.add_argument("--json", action="store_true", help="one JSON object with every record")
    p.set_defaults(func=cmd_bench_accuracy)
    p = bench.add_parser("utdmhad", parents=[common], formatter_class=DEFAULTS,
                         help="the tracker on UTD-MHAD's real Kinect depth against its skeletons (resumable)")
    p.add_argument("--out", required=True, help="folder of the per-sequence results and the table; run again "
                                                "to resume")
    p.add_argument("--modes", type=_names(MODES), default="hybrid", help="comma-separated tracker modes")
    p.add_argument("--detectors", type=_names(tuple(DETECTORS)), default="simulated",
                   help="comma-separated: simulated (from the Kinect skeleton) and/or networks on the shaded depth")
    p.add_argument("--shapes", type=_names(SHAPES), default="default",
                   help="default: the body's default shape (scaled to the person by the tracker's automatic "
                        "height unless --no-auto-height); measured: the subject's height measured on the first "
                        "frames of their sequences")
    p.add_argument("--subjects", type=_names(SUBJECTS), default=",".join(SUBJECTS), help="comma-separated subjects")
    p.add_argument("--actions", type=_names(tuple(str(a) for a in ACTIONS)), default=(),
                   help="comma-separated action numbers 1..27 (default: all)")
    p.add_argument("--frames", type=int, default=0, help="first frames of each sequence (0 = all)")
    p.add_argument("--lag", type=float, default=DEPTH_LAG_FRAMES,
                   help="frames the depth trails the Kinect skeleton in the files (measured; 0: the files' pairing)")
    p.add_argument("--seeds", type=positive_int, default=1,
                   help="PSO seeds per sequence and variant; the table and summary average over them (a change of "
                        "the search moves single sequences by 10 mm)")
    _add_assets(p)
    add_flags(p, TrackerConfig, (*BENCH_SETTINGS, "auto_height"))
    p.add_argument("--json", action="store_true", help="one JSON object with the summary and every record")
    p.set_defaults(func=cmd_bench_utdmhad)
    p = bench.add_parser("still", parents=[common], formatter_class=DEFAULTS,
                         help="jitter of a person standing still (a clip's frame held) and the lag when they move, "
                              "unsmoothed, one-Euro and centred (resumable)")
    defaults = StillPlan()
    p.add_argument("--out", required=True, help="folder of the sequences, the records and the table; run again to "
                                                "resume")
    p.add_argument("--clip", default=defaults.clip, help="the clip whose frame is held: below the assets folder, a "
                                                        "path, or builtin:NAME")
    p.add_argument("--at", type=non_negative_float, default=defaults.at_s, help="seconds into the clip of the held "
                                                                                "frame")
    p.add_argument("--hold", type=non_negative_float, default=defaults.hold_s, help="seconds the frame is held")
    p.add_argument("--moving", type=non_negative_float, default=defaults.moving_s,
                   help="seconds of the clip going on after the hold (the lag needs 0.75)")
    p.add_argument("--settle", type=non_negative_float, default=defaults.settle_s,
                   help="seconds of the track's start left out of the still frames")
    p.add_argument("--body", default=defaults.body, help="makehuman (the assets' MakeHuman body) or a body spec")
    p.add_argument("--shapes", type=_names(), default=",".join(defaults.shapes), help="comma-separated body shapes")
    p.add_argument("--yaws", type=_floats, default=",".join(f"{y:g}" for y in defaults.yaws),
                   help="comma-separated camera yaws, degrees (0: in front)")
    p.add_argument("--detectors", type=_names(tuple(DETECTORS)), default=",".join(defaults.detectors),
                   help=f"comma-separated subset of {', '.join(DETECTORS)}")
    _add_assets(p)
    add_flags(p, TrackerConfig, tuple(s for s in BENCH_SETTINGS if s != "smoothing"))
    p.add_argument("--json", action="store_true", help="one JSON object with the summary and every row")
    p.set_defaults(func=cmd_bench_still)
    p = bench.add_parser("overlays", parents=[common], formatter_class=DEFAULTS,
                         help="overlay pictures of the tracker on real Kinect frames without ground truth")
    p.add_argument("--out", default="docs/qualitative", help="folder of the pictures")
    p.add_argument("--detector", choices=[d for d in DETECTORS if d != "simulated"], default="movenet",
                   help="2D network")
    _add_assets(p)
    add_flags(p, TrackerConfig, OVERLAY_SETTINGS)
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_bench_overlays)
