"""``swarmpose subscribe``: print the poses workers publish, as they arrive."""

from __future__ import annotations

import argparse
import sys

from swarmpose.cli.common import DEFAULTS, non_negative_int, seconds
from swarmpose.core.errors import SwarmposeError
from swarmpose.publish.zenoh_options import add_zenoh_options


def add_subscribe_args(p: argparse.ArgumentParser) -> None:
    """The flags of ``swarmpose subscribe``."""
    p.add_argument("--camera", default="*", help="camera id (default: every camera)")
    p.add_argument("--count", type=non_negative_int, default=0, help="stop after this many frames (default 0 = never)")
    p.add_argument("--timeout", type=seconds, default=0.0,
                   help="stop when no frame came for this many seconds (default 0 = wait forever)")
    p.add_argument("--status", action="store_true", help="also print status messages")
    p.add_argument("--forever", action="store_true",
                   help="keep waiting when the workers end (default: exit once every worker seen has ended)")
    add_zenoh_options(p)


def cmd_subscribe(args: argparse.Namespace) -> int:
    """Print frames (and optionally status) until --count frames, --timeout, the workers' end or Ctrl-C."""
    from swarmpose.messages.describe import format_status
    from swarmpose.publish.client import Client, format_frame, say

    try:
        client = Client(args.camera, mode=args.mode, connect=args.connect, listen=args.listen,
                        multicast=not args.no_multicast, config_file=args.zenoh_config)
    except SwarmposeError as exc:
        print(f"swarmpose subscribe: error: {exc}", file=sys.stderr)
        return 2
    if args.status:
        client.on_status(lambda m: say(format_status(m)))
    say(f"listening on {client.keys['frame']} ...")
    received = 0
    try:
        with client:
            for message in client.frames(timeout=args.timeout or None, count=args.count or None,
                                         until_workers_end=not args.forever):
                received += 1
                say(format_frame(message))
            if client.workers_ended and not args.forever:
                say(f"worker {', '.join(sorted(client.ended))} ended; {received} frames received")
    except KeyboardInterrupt:
        pass
    if client.rejected:
        print(f"rejected {client.rejected} messages; last: {client.last_error}", file=sys.stderr)
    if args.count and received < args.count:
        why = (f"worker {', '.join(sorted(client.ended))} ended" if client.workers_ended
               else f"the {args.timeout:g} s timeout")
        print(f"swarmpose subscribe: got {received} of {args.count} frames before {why}", file=sys.stderr)
        return 1
    return 0


def add_subscribe_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``subscribe``."""
    p = sub.add_parser("subscribe", parents=[common], formatter_class=DEFAULTS,
                       help="print the poses workers publish over zenoh, as they arrive")
    add_subscribe_args(p)
    p.set_defaults(func=cmd_subscribe)
