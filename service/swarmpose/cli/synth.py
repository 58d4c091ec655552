"""``swarmpose synth`` (a synthetic RGBD sequence with ground truth) and ``swarmpose body``.

``synth`` films one person (``--body``, ``--shape``, ``--motion``) or a scene of several
(``--person BODY:SHAPE:MOTION[@x,z[,yaw]]`` repeated, or ``--scene FILE``; see
:mod:`swarmpose.sim.scene`), with props in the room (``--prop stool|table|box:...``, repeated, or a
scene file's ``props``; see :mod:`swarmpose.sim.props`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from swarmpose.cli.common import DEFAULTS, add_body_options, positive_int, quiet
from swarmpose.cli.settings import advanced
from swarmpose.core.errors import ConfigError

if TYPE_CHECKING:  # the body, motion and renderer are imported by the commands that use them
    from swarmpose.body.skinned import SkinnedBody
    from swarmpose.sim.scene import PersonSpec


def cmd_synth(args: argparse.Namespace) -> int:
    """Render a synthetic RGBD sequence with ground truth."""
    from swarmpose.body.loader import load_body
    from swarmpose.motion.library import load_motion_spec
    from swarmpose.sim.props import parse_prop_spec
    from swarmpose.sim.scene import load_people, read_scene_file
    from swarmpose.sim.synth import SynthConfig, synthesize, synthesize_people

    props = [parse_prop_spec(text) for text in args.prop]
    if args.scene:
        props += read_scene_file(Path(args.scene))[1]
    config = SynthConfig(frames=args.frames, fps=args.fps, seed=args.seed, camera_distance=args.camera_distance,
                         camera_yaw_deg=args.camera_yaw, camera_height=args.camera_height,
                         layout=args.layout, skinning=args.skinning,
                         clothes=args.clothes, props=tuple(props))
    config.validate()
    specs = scene_specs(args)
    if specs is not None:
        people = load_people(specs, args.frames, args.fps)
        summary = synthesize_people(people, Path(args.out), config, progress=not quiet(args))
        print_synth_summary(summary, people[0].body)
        return 0
    if args.motion is None:
        raise ConfigError("synth needs --motion (one person) or --person BODY:SHAPE:MOTION[@x,z[,yaw[,start]]] / "
                          "--scene FILE (several)")
    body = load_body(args.body, args.shape)
    motion = load_motion_spec(args.motion, body, args.frames, args.fps)
    summary = synthesize(body, motion, Path(args.out), config,
                         description={"shape": args.shape, "motion_spec": args.motion}, progress=not quiet(args))
    print_synth_summary(summary, body)
    return 0


def scene_specs(args: argparse.Namespace) -> list[PersonSpec] | None:
    """The people of ``--person`` / ``--scene``, or None when neither is given (one ``--body``)."""
    from swarmpose.sim.scene import load_scene_file, parse_person_spec

    if not args.person and not args.scene:
        return None
    if args.person and args.scene:
        raise ConfigError("give either --person (repeated) or --scene FILE, not both")
    if args.motion is not None or args.body != "builtin" or args.shape is not None:
        raise ConfigError("--body/--shape/--motion describe a single person; with --person or --scene give each "
                          "person's body, shape and motion in its spec (BODY:SHAPE:MOTION[@x,z[,yaw[,start]]])")
    return load_scene_file(Path(args.scene)) if args.scene else [parse_person_spec(p) for p in args.person]


def print_synth_summary(summary: dict, body: SkinnedBody) -> None:
    """What ``synthesize`` wrote, in three lines (and one per person of a scene)."""
    depth = summary["person_depth_m"]
    people = summary.get("people")
    if people:
        print(f"wrote {summary['frames']} frames of {len(people)} people to {summary['out']}")
    else:
        print(f"wrote {summary['frames']} frames of {summary['motion']} on {summary['body']} "
              f"(height {body.height:.2f} m) to {summary['out']}")
    print("  color/*.png depth/*.png (uint16 mm) intrinsic.json groundtruth.jsonl sequence.json")
    for prop in summary.get("props", ()):
        w, h, d = prop["world"]["size_m"]
        x, _, z = prop["world"]["centre_floor_m"]
        print(f"  {prop['kind']} ({prop['spec']}): {w:.2f} x {d:.2f} m, {h:.2f} m high, at x={x:.2f} m, z={z:.2f} m, "
              f"yaw {prop['world']['yaw_deg']:.0f} deg")
    if depth:
        print(f"  {'people' if people else 'person'} depth range: {depth[0]:.2f}..{depth[1]:.2f} m")
    for person in people or ():
        print(f"  person {person['id']}: {person['body']} (height {person['height_m']:.2f} m) doing "
              f"{person['motion']} from x={person['x']:g} m, z={person['z']:g} m, yaw {person['yaw']:g} deg; "
              f"mean visible share {person['mean_visible']:.2f}")


def cmd_body(args: argparse.Namespace) -> int:
    """Describe a body model, optionally exporting it (personalised) to GLB."""
    from swarmpose.body.gltf_write import save_glb
    from swarmpose.body.loader import load_body

    body = load_body(args.body, args.shape)
    if args.lod:
        body = body.tracking_lod(args.lod)
    info = {"name": body.name, "height_m": round(body.height, 4), "vertices": len(body.vertices),
            "triangles": len(body.triangles), "bones": len(body.bone_names)}
    if args.export:
        info["exported"] = str(save_glb(body, Path(args.export)))
    print(json.dumps(info) if args.json else "\n".join(f"{k}: {v}" for k, v in info.items()))
    return 0


def add_synth_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``synth``."""
    p = sub.add_parser("synth", parents=[common], formatter_class=DEFAULTS,
                       help="render a synthetic RGBD sequence with ground truth from a body and a motion")
    add_body_options(p)
    p.add_argument("--motion", default=None,
                   help="a BVH file (CMU, Mixamo, MakeHuman, Daz or CMU ASF joint names; FILE.bvh?map=names.toml "
                        "for your own naming, ?units=cm&up=z to state what is otherwise detected; "
                        "docs/sources-and-detectors.md) or builtin:NAME (wave, squat, walk, turn, jumping_jacks); "
                        "either may end in ?hold=[AT:]SECONDS: the frame AT s in (default 0) held still, then the "
                        "motion goes on")
    p.add_argument("--person", action="append", default=[], metavar="SPEC",
                   help="a person of a scene, repeatable: BODY:SHAPE:MOTION[@x,z[,yaw[,start]]] (README)")
    p.add_argument("--scene", default=None, metavar="FILE",
                   help="a JSON list of people {body, shape, motion, x, z, yaw, start} instead of --person, or "
                        '{"people": [...], "props": ["stool", ...]}')
    p.add_argument("--prop", action="append", default=[], metavar="SPEC",
                   help="a box in the room, repeatable: stool (under the person where the hips are lowest, as "
                        "high as the seat), table (0.75 m high, between the camera and the person, hiding the "
                        "legs), stool:K / table:K for person K, or box:x,z,w,d,h[,yaw] (footprint centre, width, "
                        "depth, height in m, world frame; yaw in degrees)")
    p.add_argument("--frames", type=positive_int, required=True, help="number of frames to write")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--seed", type=int, default=0, help="seed of the depth noise and the simulated detector")
    p.add_argument("--fps", type=float, default=30.0, help="camera frame rate; the motion is resampled to it")
    p.add_argument("--camera-distance", type=float, default=3.0,
                   help="metres from the subject's start, or from the centre of the people's starts (0.5..8)")
    p.add_argument("--camera-yaw", type=float, default=0.0, help="degrees around the subject, 0 = in front")
    advanced(p.add_argument("--camera-height", type=float, default=1.2, help="lens height above the floor, metres"))
    advanced(p.add_argument("--skinning", choices=("dqs", "lbs"), default="dqs", help="skinning of the rendered body"))
    advanced(p.add_argument("--clothes", action=argparse.BooleanOptionalAction, default=False,
                            help="colour each body by garment (skin, shirt, trousers, shoes), not one colour a "
                                 "person"))
    advanced(p.add_argument("--layout", default="coco17", help="keypoint layout of the simulated detector"))
    p.set_defaults(func=cmd_synth)


def add_body_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``body``."""
    p = sub.add_parser("body", parents=[common], formatter_class=DEFAULTS,
                       help="describe a body model; --export writes it as GLB")
    add_body_options(p)
    p.add_argument("--lod", type=int, default=0, help="decimate to about this many triangles (at least 100; 0 = no)")
    p.add_argument("--export", default=None, help="write the (personalised) body to this .glb")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_body)
