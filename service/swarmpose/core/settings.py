"""Declaring settings once: dataclass fields that carry their help, kind and limits.

A settings class (``TrackerConfig``, ``ServiceConfig``) is a frozen dataclass whose fields
are made with :func:`setting` (a leaf: one value) or :func:`section` (a nested settings
class). Everything else is generated from these declarations: the command-line flags,
the ``SWARMPOSE_<NAME>`` variables and the TOML keys (:mod:`swarmpose.cli.settings`), and the
checks of :func:`check_settings`. Leaf names are unique across a tree, so one name means
one setting everywhere (flag ``--name-with-dashes``, variable ``SWARMPOSE_NAME``, TOML key).

Kinds: ``str``, ``int``, ``float``, ``bool``, ``list`` (of strings; comma-separated in the
environment), ``size`` (``WxH`` pixels -> ``(w, h)``) and ``float?`` (a number or none).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, Field, field, fields, is_dataclass, replace
from typing import Any, TypeVar

from swarmpose.core.errors import ConfigError

KINDS = ("str", "int", "float", "bool", "list", "size", "float?")
_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off", ""}
_NONE = {"", "none", "null", "auto"}
T = TypeVar("T")
HELP_MAX = 110
"""The longest help text of a setting (characters): two lines of ``--help`` with its default."""


def parse_bool(text: str) -> bool:
    """``1/true/yes/on`` or ``0/false/no/off/''`` (any case, spaces ignored) -> bool; ValueError otherwise."""
    value = str(text).strip().lower()
    if value in _TRUE | _FALSE:
        return value in _TRUE
    raise ValueError(text)


def setting(default: Any, help: str, *, kind: str | None = None, choices: tuple[str, ...] = (),
            minimum: float | None = None, maximum: float | None = None, aliases: tuple[str, ...] = (),
            everyday: bool = False) -> Any:
    """A leaf setting. kind: inferred from ``default`` unless given; choices: allowed values
    (str); minimum / maximum: inclusive numeric limits; aliases: older names still accepted;
    everyday: its flag shows in a command's ``--help`` (the others only in ``--help-all``).
    help: what it does, in at most :data:`HELP_MAX` characters."""
    if kind is None:
        kind = {bool: "bool", int: "int", float: "float", tuple: "list", str: "str"}[type(default)]
    if kind not in KINDS:
        raise ValueError(f"unknown setting kind {kind!r}")
    if len(help) > HELP_MAX:
        raise ValueError(f"the help of a setting is {len(help)} characters (at most {HELP_MAX}): {help!r}")
    meta = {"help": help, "kind": kind, "choices": tuple(choices), "minimum": minimum, "maximum": maximum,
            "aliases": tuple(aliases), "everyday": everyday}
    return field(default=default, metadata=meta)


def section(cls: type, help: str) -> Any:
    """A nested settings class (its leaves are settings of the outer class too)."""
    return field(default_factory=cls, metadata={"help": help, "section": cls})


def leaves(cls: type) -> dict[str, tuple[tuple[str, ...], Field]]:
    """Every leaf setting of ``cls`` and its sections: name -> (path of section names, field)."""
    out: dict[str, tuple[tuple[str, ...], Field]] = {}
    for f in fields(cls):
        sub = f.metadata.get("section")
        if sub is not None:
            for name, (path, leaf) in leaves(sub).items():
                out[name] = ((f.name, *path), leaf)
        elif "kind" in f.metadata:
            if f.name in out:
                raise ValueError(f"setting {f.name!r} is declared twice in {cls.__name__}")
            out[f.name] = ((), f)
    return out


def default_of(f: Field) -> Any:
    """The default value of a leaf field."""
    return f.default if f.default is not MISSING else f.default_factory()  # type: ignore[misc]


SIZE_MIN, SIZE_MAX = 8, 512
"""The sides (pixels) a ``size`` setting (the depth tile) may have. The OpenCL scorer also refuses,
naming its device, a tile that device's local memory cannot hold (4 bytes a pixel)."""


def check_size(value: Any, name: str = "size") -> tuple[int, int]:
    """``value`` as a (W, H) pair of whole pixels within SIZE_MIN..SIZE_MAX; ConfigError otherwise."""
    if (not isinstance(value, tuple) or len(value) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        raise ConfigError(f"{name} must be WxH pixels, e.g. 64x64 or (64, 64); got {value!r}")
    w, h = value
    if not (SIZE_MIN <= w <= SIZE_MAX and SIZE_MIN <= h <= SIZE_MAX):
        raise ConfigError(f"{name} sides must be within {SIZE_MIN}..{SIZE_MAX} pixels; got {w}x{h}")
    return w, h


def parse_size(text: str, name: str = "size") -> tuple[int, int]:
    """``"64x48"`` -> ``(64, 48)`` (sides SIZE_MIN..SIZE_MAX px); ConfigError otherwise. The one WxH parser."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ConfigError(f"{name} must be WxH pixels, e.g. 64x64; got {text!r}") from None
    return check_size((w, h), name)


def format_value(value: Any) -> str:
    """A setting's value as a user writes it (for ``--help`` defaults and messages)."""
    if isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, int) for v in value):
        return f"{value[0]}x{value[1]}"
    if isinstance(value, tuple):
        return ",".join(value) or "none"
    if value is None:
        return "auto"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value) if value != "" else '""'


def convert(name: str, kind: str, value: Any, origin: str) -> Any:
    """``value`` (from a file, a variable or a flag) as a setting of ``kind``; ConfigError naming
    ``origin`` otherwise."""
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
            return parse_bool(value)
        if kind == "size":
            if isinstance(value, (list, tuple)) and len(value) == 2:
                value = f"{value[0]}x{value[1]}"
            return parse_size(value, name)
        if kind in ("int", "float", "float?"):
            if isinstance(value, bool):
                raise ValueError
            if kind == "float?" and (value is None or str(value).strip().lower() in _NONE):
                return None
            if kind == "int":
                if isinstance(value, float) and not value.is_integer():
                    raise ValueError
                return int(value)
            return float(value)
        if not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise ValueError
        return str(value)
    except (TypeError, ValueError):
        expected = {"list": "a list of strings (comma-separated in the environment)",
                    "bool": "a boolean (true/false, 1/0, yes/no, on/off)", "int": "an integer",
                    "float": "a number", "float?": "a number or 'auto'", "str": "a string",
                    "size": "WxH pixels"}[kind]
        raise ConfigError(f"{origin}: {name} = {value!r} is not {expected}") from None
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}") from None


def check_settings(obj: Any) -> None:
    """ConfigError naming the first leaf of ``obj`` (a settings dataclass) outside its choices or limits."""
    for f in fields(obj):
        if "kind" not in f.metadata:
            continue
        value, meta = getattr(obj, f.name), f.metadata
        if meta["choices"] and value not in meta["choices"]:
            raise ConfigError(f"{f.name} must be one of {', '.join(meta['choices'])}; got {value!r}")
        if meta["kind"] == "size":
            check_size(value, f.name)
        if meta["kind"] in ("int", "float", "float?") and value is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{f.name} must be a finite number; got {value!r}")
            if meta["minimum"] is not None and value < meta["minimum"]:
                raise ConfigError(f"{f.name} must be at least {meta['minimum']:g}; got {value}")
            if meta["maximum"] is not None and value > meta["maximum"]:
                raise ConfigError(f"{f.name} must be at most {meta['maximum']:g}; got {value}")


def is_settings(cls: Any) -> bool:
    """True for a settings dataclass (one with :func:`setting` fields)."""
    return is_dataclass(cls) and any("kind" in f.metadata or "section" in f.metadata for f in fields(cls))


def build(cls: type[T], values: Mapping[str, Any]) -> T:
    """An instance of ``cls`` from leaf values by name (sections built from their leaves)."""
    kwargs: dict[str, Any] = {}
    for f in fields(cls):
        sub = f.metadata.get("section")
        if sub is not None:
            kwargs[f.name] = build(sub, {k: v for k, v in values.items() if k in leaves(sub)})
        elif f.name in values:
            kwargs[f.name] = values[f.name]
    return cls(**kwargs)


def with_settings(config: T, **changes: Any) -> T:
    """A copy of a settings object with leaf settings changed by name (sections included),
    each value converted as a flag's, a variable's or a file's is (``"32x48"``, ``[32, 48]``);
    ConfigError for a name it does not have or a value of the wrong type or out of range."""
    known = leaves(type(config))
    unknown = sorted(set(changes) - set(known))
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(unknown)}; settings are {', '.join(sorted(known))}")
    changes = {name: convert(name, known[name][1].metadata["kind"], value, f"argument {name}")
               for name, value in changes.items()}
    out = config
    for f in fields(config):
        sub = f.metadata.get("section")
        if sub is not None:
            mine = {k: v for k, v in changes.items() if k in leaves(sub)}
            if mine:
                out = replace(out, **{f.name: with_settings(getattr(config, f.name), **mine)})
    direct = {k: v for k, v in changes.items() if k in {f.name for f in fields(config)}}
    return replace(out, **direct) if direct else out
