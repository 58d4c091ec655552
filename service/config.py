"""Configuration of the service (``swarmpose serve`` / ``replay``): one frozen dataclass.

Layers, later ones win: the defaults below < a TOML file (``--config FILE`` or
``$SWARMPOSE_CONFIG``) < environment variables ``SWARMPOSE_<NAME>`` (e.g.
``SWARMPOSE_SOURCE``, ``SWARMPOSE_CAMERA_ID``, ``SWARMPOSE_CONNECT``) < command-line flags.
In the file, keys are the field names (``camera_id`` or ``camera-id``); in the environment,
lists are comma-separated and booleans are 1/0, true/false, yes/no, on/off.

Every wrong value raises :class:`~swarmpose.errors.ConfigError` naming the key, where it
came from (file, variable or flag) and what is allowed.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path

from .errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ENV_PREFIX = "SWARMPOSE_"
ENV_CONFIG = "SWARMPOSE_CONFIG"
ZENOH_MODES = ("peer", "client", "off")
TRACK_MODES = ("hybrid", "depth", "joints", "lift")
PSO_VARIANTS = ("perturbed", "canonical")


@dataclass(frozen=True)
class ServiceConfig:
    """What ``serve`` and ``replay`` run.

    source: frame-source URI (folder:DIR, bag:FILE, realsense:, azure:, openni2:, ...);
    camera_id: the ``<camera>`` of the zenoh keys; joints: detector spec; body / shape: the
    body model; mode / particles / generations / pso / tile / triangles / seed / device: the
    tracker; zenoh_mode: peer (default), client or off; connect / listen: zenoh endpoints
    (e.g. tcp/192.168.1.10:7447); multicast: zenoh multicast scouting (peer discovery on the
    LAN); zenoh_config: a zenoh JSON5 configuration file applied first; rate: pace a recording
    at this many frames/s (0 = as recorded for serve, as fast as possible for replay; live
    cameras set their own rate); loop: start a recording over when it ends (serve);
    record: also write the replay files into this folder (serve); status_period_s: seconds
    between status messages; health_file: where each status is also written for ``swarmpose
    health`` ("" = nowhere); reopen_s: seconds between attempts to reopen a failed live
    source; max_frames: stop after this many frames (0 = no limit).
    """

    source: str = ""
    camera_id: str = "camera0"
    joints: str = "simulated"
    body: str = "builtin"
    shape: str = ""
    mode: str = "hybrid"
    particles: int = 64
    generations: int = 64
    pso: str = "perturbed"
    tile: str = "64x64"
    triangles: int = 1500
    seed: int = 0
    device: str = ""
    zenoh_mode: str = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast: bool = True
    zenoh_config: str = ""
    rate: float = 0.0
    loop: bool = False
    record: str = ""
    status_period_s: float = 1.0
    health_file: str = ""
    reopen_s: float = 5.0
    max_frames: int = 0
    overlay: bool = True

    def __post_init__(self) -> None:
        from .messages import check_camera_id

        check_camera_id(self.camera_id)
        _choice("zenoh_mode", self.zenoh_mode, ZENOH_MODES)
        _choice("mode", self.mode, TRACK_MODES)
        _choice("pso", self.pso, PSO_VARIANTS)
        for name in ("particles", "generations", "triangles"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be at least 1, got {getattr(self, name)}")
        for name in ("rate", "reopen_s", "max_frames"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ConfigError(f"{name} must be a finite number, 0 or more, got {getattr(self, name)}")
        if not (math.isfinite(self.status_period_s) and self.status_period_s > 0):
            raise ConfigError(f"status_period_s must be a finite positive number, got {self.status_period_s}")
        _ = self.tile_size  # raises ConfigError for a malformed tile

    @property
    def tile_size(self) -> tuple[int, int]:
        """The depth tile as (width, height) pixels."""
        try:
            w, h = (int(v) for v in self.tile.lower().split("x"))
        except ValueError:
            raise ConfigError(f"tile must be WxH, e.g. 64x64, got {self.tile!r}") from None
        if not (8 <= w <= 512 and 8 <= h <= 512):
            raise ConfigError(f"tile sides must be within 8..512, got {self.tile!r}")
        return w, h

    def require_source(self) -> ServiceConfig:
        """Self, or a ConfigError when no source is configured."""
        if not self.source:
            raise ConfigError("no source: pass --source URI (folder:DIR, bag:FILE, mkv:FILE, realsense:, azure:, "
                              "openni2:[FILE.oni]) or set SWARMPOSE_SOURCE")
        return self


def _choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ConfigError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")


FIELDS = {f.name: f for f in fields(ServiceConfig)}


def _field_kind(name: str) -> str:
    default = FIELDS[name].default
    return {bool: "bool", int: "int", float: "float", tuple: "list"}.get(type(default), "str")


_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off", ""}


def convert(name: str, value, origin: str):
    """``value`` (from a file, variable or flag) as the type of field ``name``; ConfigError otherwise."""
    kind = _field_kind(name)
    try:
        if kind == "list":
            if isinstance(value, str):
                return tuple(v.strip() for v in value.split(",") if v.strip())
            if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
                return tuple(value)
            raise ValueError
        if kind == "bool":
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in _TRUE | _FALSE:
                return text in _TRUE
            raise ValueError
        if kind == "int":
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise ValueError
            return int(value)
        if kind == "float":
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        if not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise ValueError
        return str(value)
    except (TypeError, ValueError):
        expected = {"list": "a list of strings (comma-separated in the environment)",
                    "bool": "a boolean (true/false, 1/0, yes/no, on/off)", "int": "an integer",
                    "float": "a number", "str": "a string"}[kind]
        raise ConfigError(f"{origin}: {name} = {value!r} is not {expected}") from None


def read_toml(path: str | Path) -> dict:
    """The settings of a TOML config file (top level or a ``[swarmpose]`` table)."""
    path = Path(path).expanduser()
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"config file {path} does not exist; pass an existing TOML file to --config") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"config file {path} cannot be read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {path} is not valid TOML: {exc}") from None
    data = data.get("swarmpose", data)
    settings = {}
    for key, value in data.items():
        name = key.replace("-", "_")
        if name not in FIELDS:
            raise ConfigError(f"config file {path}: unknown key {key!r}; keys are {', '.join(sorted(FIELDS))}")
        settings[name] = convert(name, value, f"config file {path}")
    return settings


def from_environment(env: Mapping[str, str]) -> dict:
    """The settings of ``SWARMPOSE_<NAME>`` variables (names of :class:`ServiceConfig` fields)."""
    settings = {}
    for name in FIELDS:
        var = ENV_PREFIX + name.upper()
        if var in env:
            settings[name] = convert(name, env[var], f"environment variable {var}")
    return settings


def load_config(flags: Mapping[str, object] | None = None, config_file: str | None = None,
                env: Mapping[str, str] | None = None, defaults: Mapping[str, object] | None = None) -> ServiceConfig:
    """``defaults`` (a command's own, over the dataclass') < ``config_file`` (or
    ``$SWARMPOSE_CONFIG``) < environment < ``flags`` (field name -> value; None = not given)."""
    env = os.environ if env is None else env
    settings: dict = dict(defaults or {})
    origins: dict[str, str] = {}
    path = config_file or env.get(ENV_CONFIG)
    if path:
        from_file = read_toml(path)
        settings.update(from_file)
        origins.update({name: f"config file {path}" for name in from_file})
    from_env = from_environment(env)
    settings.update(from_env)
    origins.update({name: f"environment variable {ENV_PREFIX}{name.upper()}" for name in from_env})
    for name, value in (flags or {}).items():
        if value is None:
            continue
        if name not in FIELDS:
            raise ConfigError(f"unknown setting {name!r}")
        settings[name] = convert(name, value, f"flag --{name.replace('_', '-')}")
        origins[name] = f"flag --{name.replace('_', '-')}"
    try:
        return ServiceConfig(**settings)
    except ConfigError as exc:
        text = str(exc)
        culprit = next((n for n in origins if text.startswith(n) or text.startswith(n.replace("_", " "))), None)
        raise ConfigError(f"{origins[culprit]}: {text}" if culprit else text) from None


__all__ = ["ServiceConfig", "load_config", "read_toml", "from_environment"]
