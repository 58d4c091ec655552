"""Every command's ``--help`` fits a screen (the everyday options); ``--help-all`` shows every option."""

from __future__ import annotations

import argparse

import pytest

from swarmpose.cli.main import build_parser
from swarmpose.core.settings import HELP_MAX, setting

EVERYDAY = ("--source", "--out", "--body", "--shape", "--detector", "--models", "--max-people", "--coordinates",
            "--view", "--config", "--verbose", "--quiet", "--help-all")
"""What ``track --help`` must show (the issue's list: source, out, body and shape, detector and models,
people, coordinates, view, config, verbosity)."""
HELP_LINES = 40


def commands(parser: argparse.ArgumentParser,
             prefix: tuple[str, ...] = ()) -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every (sub)command's parser, by its words (``("bench", "live")``)."""
    found = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if sub in found.values():  # an alias (personalise)
                    continue
                found[(*prefix, name)] = sub
                found.update(commands(sub, (*prefix, name)))
    return found


def printed(words: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(words)
    assert exit_.value.code == 0
    return capsys.readouterr().out


@pytest.fixture(autouse=True)
def eighty_columns(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")


def test_every_commands_help_fits_in_forty_lines_and_help_all_shows_every_option(capsys):
    found = commands(build_parser())
    assert {("track",), ("serve",), ("bench", "live"), ("bench", "accuracy"), ("personalize",)} <= set(found)
    for words, parser in found.items():
        if any(isinstance(a, argparse._SubParsersAction) for a in parser._actions):
            continue  # `bench` lists its benchmarks
        short = printed([*words, "--help"], capsys)
        assert len(short.splitlines()) <= HELP_LINES, (words, len(short.splitlines()))
        full = printed([*words, "--help-all"], capsys)
        for action in parser._actions:
            for flag in action.option_strings:
                assert flag in full, (words, flag)
        assert len(full) >= len(short)


def test_track_help_shows_the_everyday_options_and_help_all_the_research_knobs(capsys):
    short = printed(["track", "--help"], capsys)
    for flag in EVERYDAY:
        assert flag in short, flag
    for knob in ("--particles", "--polish", "--hypotheses", "--lost-depth-agreement", "--floor"):
        assert knob not in short, knob
    full = printed(["track", "--help-all"], capsys)
    assert "advanced tracker settings:" in full and "--particles PARTICLES" in full
    assert "usage: swarmpose track [options] --out OUT [SEQ]" in short


def test_an_advanced_flag_still_parses_and_an_error_prints_a_short_usage(capsys):
    args = build_parser().parse_args(["track", "x", "--out", "o", "--particles", "12"])
    assert args.particles == "12"
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["track", "x", "--out", "o", "--coordinates", "foo"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'foo'" in err and len(err.splitlines()) <= 3


def test_a_setting_with_a_help_longer_than_two_lines_is_refused_where_it_is_declared():
    setting(1, "x" * HELP_MAX)
    with pytest.raises(ValueError, match="at most"):
        setting(1, "x" * (HELP_MAX + 1))
