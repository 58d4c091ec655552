"""The house rules of the package: the tree, pyproject, the README's map and the tests agree;
modules stay small; every tracker setting is settable the same way on every command."""

from __future__ import annotations

import re
import sys
from pathlib import Path

from swarmpose.cli.main import build_parser
from swarmpose.core.settings import leaves
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.features import unavailable_settings
from swarmpose.tracking.config import TrackerConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[1]
SERVICE = REPO / "service" / "swarmpose"
MAX_LINES = 420


def stages() -> set[str]:
    return {p.parent.name for p in SERVICE.glob("*/__init__.py")}


def test_pyproject_ships_every_package():
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    assert listed == {"swarmpose", "swarmpose.cl", "swarmpose.protocol"} | {f"swarmpose.{s}" for s in stages()}


def test_the_readme_map_matches_the_tree_and_the_tests_mirror_it():
    readme = (REPO / "README.md").read_text()
    block = readme.split("## Where things are", 1)[1].split("```", 2)[1]
    mapped = set(re.findall(r"^  ([a-z_]+)/", block, flags=re.M))
    assert mapped == stages()
    test_dirs = {p.name for p in (REPO / "tests").iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert test_dirs - {"docker"} <= stages()


def test_no_module_is_long():
    long = {str(p.relative_to(REPO)): n for p in SERVICE.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"split these modules: {long}"


def test_every_tracker_setting_is_a_flag_of_every_tracking_command_that_can_run_it():
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices
    refused = {"threaded": {"--" + name for name in unavailable_settings("threaded")}}
    tracker = {"--" + name.replace("_", "-") for name in leaves(TrackerConfig)}
    shared = {"--source", "--detector", "--body", "--shape", "--frames", "--camera-id", "--overlay", "--config"}
    for command, driver in (("track", "offline"), ("eval", "offline"), ("serve", "threaded"), ("replay", "threaded")):
        flags = {s for a in commands[command]._actions for s in a.option_strings}
        wanted = (tracker | shared) - refused.get(driver, set())
        assert wanted <= flags, (command, sorted(wanted - flags))
    service_flags = {s for a in commands["serve"]._actions for s in a.option_strings}
    assert {"--" + n.replace("_", "-") for n in leaves(ServiceConfig)} - refused["threaded"] <= service_flags
