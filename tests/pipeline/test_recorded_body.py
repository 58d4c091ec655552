"""eval / replay / track warn when the body tracking a synth sequence is not the one it was rendered with."""

from __future__ import annotations

import logging
from contextlib import ExitStack

import pytest

from swarmpose.cli.main import main
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.service import open_parts


@pytest.fixture(scope="module")
def female_sequence(tmp_path_factory):
    out = tmp_path_factory.mktemp("female")
    assert main(["synth", "--body", "builtin", "--shape", "female", "--motion", "builtin:wave", "--frames", "2",
                 "--out", str(out), "--quiet"]) == 0
    return out


def _warnings(caplog, config: ServiceConfig) -> list[str]:
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="swarmpose"), ExitStack() as stack:
        open_parts(config, stack, score=False)
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


def test_another_body_than_the_recorded_one_is_named_in_a_warning(female_sequence, caplog):
    found = _warnings(caplog, ServiceConfig(source=str(female_sequence), body="builtin", overlay=False))
    assert len(found) == 1
    assert "builtin:female" in found[0] and "tracked with builtin" in found[0] and "--shape" in found[0]


def test_the_recorded_body_tracks_without_a_warning(female_sequence, caplog):
    assert _warnings(caplog, ServiceConfig(source=str(female_sequence), body="builtin", shape="female",
                                           overlay=False)) == []


def test_the_eval_command_prints_the_warning(female_sequence, tmp_path, capsys):
    assert main(["eval", "--source", str(female_sequence), "--mode", "lift", "--out", str(tmp_path / "o"),
                 "--no-overlay", "--quiet"]) == 0
    assert "was rendered with the body builtin:female" in capsys.readouterr().err
