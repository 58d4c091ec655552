"""The zenoh options of the client's tools (``swarmpose subscribe``, the example subscriber), in a module
the command line can read without loading the client."""

from __future__ import annotations

import argparse


def add_zenoh_options(p: argparse.ArgumentParser) -> None:
    """--mode/--connect/--listen/--no-multicast/--zenoh-config, as zenoh's own tools have them."""
    p.add_argument("--mode", choices=("peer", "client"), default="peer", help="zenoh mode (default peer)")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="zenoh endpoint to listen on")
    p.add_argument("--no-multicast", action="store_true", help="turn zenoh multicast scouting off")
    p.add_argument("--zenoh-config", default="", help="a zenoh JSON5 configuration file")
