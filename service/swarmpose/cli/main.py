"""The ``swarmpose`` command line: one entry point, one subcommand per job.

Errors raised on purpose (:class:`swarmpose.core.errors.SwarmposeError`) print one line on
stderr and exit with status 2; argparse reports bad flags the same way. ``-v`` / ``-q``
(before or after the subcommand) turn the log up (debug) or down (warnings only, no
progress bars). SIGTERM stops a command as Ctrl-C does (exit status 130, files closed).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from swarmpose import __version__
from swarmpose.cli.bench import add_bench_commands
from swarmpose.cli.common import DEFAULTS, verbosity_parent
from swarmpose.cli.demo import add_demo_command
from swarmpose.cli.models import add_models_command
from swarmpose.cli.personalize import add_personalize_command
from swarmpose.cli.probe import add_probe_command
from swarmpose.cli.serve import add_service_commands
from swarmpose.cli.subscribe import add_subscribe_command
from swarmpose.cli.synth import add_body_command, add_synth_command
from swarmpose.cli.track import add_track_commands
from swarmpose.cli.view import add_view_command
from swarmpose.core.errors import SwarmposeError


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    common = verbosity_parent()
    parser = argparse.ArgumentParser(prog="swarmpose", parents=[verbosity_parent(top=True)],
                                     description="markerless 3D human pose tracking for RGBD cameras",
                                     formatter_class=DEFAULTS)
    parser.add_argument("--version", action="version", version=f"swarmpose {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_synth_command(sub, common)
    add_demo_command(sub, common)
    add_track_commands(sub, common)
    add_service_commands(sub, common)
    add_subscribe_command(sub, common)
    add_probe_command(sub, common)
    add_bench_commands(sub, common)
    add_body_command(sub, common)
    add_personalize_command(sub, common)
    add_view_command(sub, common)
    add_models_command(sub, common)
    return parser


def configure_logging(verbosity: int) -> None:
    """The ``swarmpose`` logger on stderr: warnings (verbosity < 0), info (0) or debug (> 0)."""
    level = logging.WARNING if verbosity < 0 else logging.DEBUG if verbosity > 0 else logging.INFO
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("swarmpose: %(message)s" if verbosity <= 0 else
                                           "%(asctime)s %(name)s %(levelname)s: %(message)s"))
    root = logging.getLogger("swarmpose")
    for old in [h for h in root.handlers if getattr(h, "_swarmpose_cli", False)]:
        root.removeHandler(old)
    handler._swarmpose_cli = True  # type: ignore[attr-defined]
    root.addHandler(handler)
    root.setLevel(level)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    args.verbosity = getattr(args, "verbose", 0) - getattr(args, "quiet", 0)
    configure_logging(args.verbosity)
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _interrupt) if main_thread else None
    try:
        return int(args.func(args) or 0)
    except SwarmposeError as exc:
        print(f"swarmpose: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("swarmpose: interrupted", file=sys.stderr)
        return 130
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM ends a command as Ctrl-C does, so its open files are flushed and closed on the way out
    (``serve`` and ``replay`` put their own handler in place: they stop the worker)."""
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(main())
