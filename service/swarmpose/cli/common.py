"""Pieces every subcommand shares: verbosity flags, positive integers, body options."""

from __future__ import annotations

import argparse
import math
import signal
from collections.abc import Callable
from contextlib import ExitStack

INTERRUPTED = 130
"""The exit status of a run SIGINT or SIGTERM stopped (its files closed, holding every frame tracked)."""
INTERRUPTED_NOTE = "interrupted; the outputs hold the frames tracked so far"


def stop_on_signals(stop: Callable[[], object], stack: ExitStack) -> None:
    """SIGINT and SIGTERM call ``stop()``; ``stack`` puts the previous handlers back."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous = signal.signal(sig, lambda *_: stop())
        stack.callback(signal.signal, sig, previous)


class DefaultsFormatter(argparse.HelpFormatter):
    """Help that shows each option's default, unless its text already does or there is none; its
    usage line names the positionals and required options, the rest as ``[options]``."""

    def _format_usage(self, usage, actions, groups, prefix):  # noqa: ANN001, ANN202 (argparse's signature)
        if usage is not None:
            return super()._format_usage(usage, actions, groups, prefix)
        named = [a for a in actions if (not a.option_strings or a.required) and a.help is not argparse.SUPPRESS]
        text = super()._format_usage(None, named, [], prefix)
        return text.replace(self._prog, f"{self._prog} [options]", 1) if len(named) < len(actions) else text

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if ("(default" in text or not action.option_strings or action.default in (None, False, "", [])
                or action.default is argparse.SUPPRESS):
            return text
        return text + " (default: %(default)s)"


DEFAULTS = DefaultsFormatter


def verbosity_parent(top: bool = False) -> argparse.ArgumentParser:
    """``-v/--verbose`` and ``-q/--quiet`` (counted), accepted before and after the subcommand."""
    p = argparse.ArgumentParser(add_help=False)
    default = 0 if top else argparse.SUPPRESS
    p.add_argument("-v", "--verbose", action="count", default=default, help="more log output (debug)")
    p.add_argument("-q", "--quiet", action="count", default=default,
                   help="less output: warnings only, no progress bars")
    from swarmpose.cli.settings import HelpAll

    p.add_argument("--help-all", action=HelpAll)
    return p


def quiet(args: argparse.Namespace) -> bool:
    """True when progress bars should stay off."""
    return getattr(args, "verbosity", 0) < 0


def positive_int(text: str) -> int:
    """An argparse type: an integer of at least 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """An argparse type: an integer of at least 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def _non_negative(text: str, what: str) -> float:
    """``text`` as a finite number, 0 or more; else an argparse error that calls it ``what``."""
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be {what}, 0 or more, got {text}")
    return value


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number, 0 or more."""
    return _non_negative(text, "a number")


def seconds(text: str) -> float:
    """An argparse type: a finite number of seconds, 0 or more."""
    return _non_negative(text, "a number of seconds")


def add_body_options(p: argparse.ArgumentParser) -> None:
    """``--body`` and ``--shape`` for the commands that take no other settings."""
    p.add_argument("--body", default="builtin", help="'builtin', 'makehuman:DIR' or a .glb/.gltf file")
    p.add_argument("--shape", default=None,
                   help="body shape: a preset (male, female, ...) or sliders (height=1.8,... or gender=0.3,...)")
