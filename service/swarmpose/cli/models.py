"""``swarmpose models`` (where the 2D networks are looked for and what is found) and
``swarmpose models add FILE`` (install a downloaded network into the user's models folder)."""

from __future__ import annotations

import argparse
import json

from swarmpose.cli.common import DEFAULTS


def cmd_models(args: argparse.Namespace) -> int:
    """List the models folders in search order and the named networks found in them."""
    from swarmpose.detect.models import found_models

    folders, found = found_models(args.models or "")
    if args.json:
        print(json.dumps({"folders": [str(f) for f in folders],
                          "models": [{"name": m.name, "path": str(m.path), "bytes": m.size, "layout": m.layout,
                                      "licence": m.licence, "used": m.used} for m in found]}))
        return 0
    print("models folders, searched in this order:")
    for folder in folders:
        print(f"  {folder}{'' if folder.is_dir() else '  (absent)'}")
    if not found:
        print("no network found: download MoveNet or BlazePose (README, '2D joints') and run "
              "`swarmpose models add FILE.onnx`")
        return 0
    print("networks found (--detector NAME runs the first of its name):")
    for m in found:
        mark = "*" if m.used else " "
        print(f" {mark} {m.name:10s} {m.size / 1e6:6.1f} MB  {m.layout}  {m.path}  [{m.licence}]")
    return 0


def cmd_models_add(args: argparse.Namespace) -> int:
    """Check a downloaded network with onnxruntime and install it into the user's models folder."""
    from swarmpose.detect.models import add_model

    name, path = add_model(args.file, force=args.force)
    print(f"installed {name} as {path}; run it with --detector {name}")
    return 0


def add_models_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``models`` and ``models add``."""
    p = sub.add_parser("models", parents=[common], formatter_class=DEFAULTS,
                       help="where the 2D networks are looked for and what is found; `models add FILE` installs one")
    p.add_argument("--models", default=None, help="a models folder searched first (as --models of the other commands)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=cmd_models)
    actions = p.add_subparsers(dest="models_action", metavar="ACTION")
    add = actions.add_parser("add", parents=[common], formatter_class=DEFAULTS,
                             help="check an ONNX pose network and install it into the user's models folder")
    add.add_argument("file", metavar="FILE", help="the downloaded .onnx (MoveNet single-pose or BlazePose full)")
    add.add_argument("--force", action="store_true", help="replace an installed network of the same name")
    add.set_defaults(func=cmd_models_add)
