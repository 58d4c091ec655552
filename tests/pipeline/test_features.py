"""The table of which driver runs which feature decides the refusals and the flags commands offer."""

from __future__ import annotations

import pytest

from swarmpose.cli.main import build_parser
from swarmpose.core.errors import ConfigError
from swarmpose.pipeline.features import DRIVERS, FEATURES, refuse, unavailable_settings
from swarmpose.tracking.config import TrackerConfig

ASKING = {"backward": {"backward": 5}, "ensemble": {"ensemble": 3}, "smoothing": {"smoothing": "centred"}}
REFUSED = {("threaded", "backward"), ("frame_by_frame", "backward"), ("threaded", "ensemble"),
           ("threaded", "smoothing"), ("frame_by_frame", "smoothing")}
"""What the docs promise: the backward pass and centred smoothing need the frames after each one
(offline only); the ensemble runs its tracks in one thread (not in serve and replay)."""


@pytest.mark.parametrize("driver", DRIVERS)
@pytest.mark.parametrize("feature", FEATURES, ids=lambda f: f.setting)
def test_a_driver_refuses_exactly_the_features_the_docs_say_it_cannot_run(driver, feature):
    config = TrackerConfig(**ASKING[feature.setting])
    assert set(DRIVERS) == {"offline", "threaded", "frame_by_frame"} and {f.setting for f in FEATURES} == set(ASKING)
    if (driver, feature.setting) not in REFUSED:
        refuse(driver, config)
    else:
        with pytest.raises(ConfigError, match=f"{feature.setting} = .*: not in .*; run "):
            refuse(driver, config)


def test_the_defaults_and_live_smoothing_run_everywhere():
    for driver in DRIVERS:
        refuse(driver, TrackerConfig())
        refuse(driver, TrackerConfig(smoothing="one-euro"))
    with pytest.raises(ValueError, match="unknown driver"):
        refuse("batch", TrackerConfig())


def test_a_command_never_offers_a_flag_its_driver_refuses():
    parser = build_parser()
    subcommands = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction").choices
    assert set(unavailable_settings("threaded")) == {"backward", "ensemble"}
    assert unavailable_settings("offline") == ()
    for command in ("serve", "replay"):
        flags = {f for a in subcommands[command]._actions for f in a.option_strings}
        assert not {"--backward", "--ensemble"} & flags and "--smoothing" in flags, command
    for command in ("track", "eval"):
        flags = {f for a in subcommands[command]._actions for f in a.option_strings}
        assert {"--backward", "--ensemble", "--smoothing"} <= flags, command
