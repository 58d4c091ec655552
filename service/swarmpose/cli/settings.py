"""Settings from the command line, the environment and a TOML file, in layers.

Later layers win: the defaults (the dataclass', then a command's own) < a TOML file
(``--config FILE`` or ``$SWARMPOSE_CONFIG``; keys are setting names, at the top level and in a
``[swarmpose]`` table, each with section tables such as ``[tracker]`` and ``[zenoh]``; a
setting given twice is an error) <
environment variables ``SWARMPOSE_<NAME>`` < flags. Flags are generated from the settings'
declarations (:mod:`swarmpose.core.settings`), each showing its default; a wrong value
anywhere raises :class:`~swarmpose.core.errors.ConfigError` naming the setting, where it
came from and what is allowed.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable, Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any, TypeVar

from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import build, convert, default_of, format_value, leaves
from swarmpose.core.toml_file import read_toml_file

ENV_PREFIX = "SWARMPOSE_"
ENV_CONFIG = "SWARMPOSE_CONFIG"
T = TypeVar("T")


def aliases(cls: type) -> dict[str, str]:
    """Older names of settings -> their current name."""
    return {alias: name for name, (_, f) in leaves(cls).items() for alias in f.metadata["aliases"]}


def environment_names(cls: type) -> dict[str, str]:
    """Every ``SWARMPOSE_*`` variable ``cls`` reads -> its setting (aliases included)."""
    names = {ENV_PREFIX + name.upper(): name for name in leaves(cls)}
    names.update({ENV_PREFIX + alias.upper(): name for alias, name in aliases(cls).items()})
    return names


def add_flags(parser: argparse.ArgumentParser, cls: type, only: Iterable[str] | None = None,
              defaults: Mapping[str, Any] | None = None) -> None:
    """One flag per leaf setting of ``cls`` (or those in ``only``), default None so the other
    layers show through; the help shows each default (``defaults`` over the dataclass'). The
    everyday settings show in ``--help``, the others in an "advanced" group only ``--help-all``
    shows (:func:`advanced`)."""
    wanted = None if only is None else set(only)
    groups: dict[str, argparse._ArgumentGroup] = {}
    for name, (path, f) in leaves(cls).items():
        if wanted is not None and name not in wanted:
            continue
        meta = f.metadata
        group: argparse.ArgumentParser | argparse._ArgumentGroup = parser
        if not meta["everyday"]:
            title = f"advanced {path[0]} settings" if path else "advanced settings"
            group = groups.get(title) or groups.setdefault(title, parser.add_argument_group(title))
        default = (defaults or {}).get(name, default_of(f))
        flag = "--" + name.replace("_", "-")
        names = [flag] + ["--" + a.replace("_", "-") for a in meta["aliases"]]
        text = f"{meta['help']} (default: {format_value(default)})"
        if meta["kind"] == "bool":
            action = group.add_argument(*names, dest=name, default=None, action=argparse.BooleanOptionalAction,
                                        help=text)
        elif meta["kind"] == "list":
            action = group.add_argument(*names, dest=name, default=None, action="append", metavar="VALUE",
                                        help=text + "; repeatable")
        else:
            action = group.add_argument(*names, dest=name, default=None, help=text, choices=meta["choices"] or None,
                                        metavar=None if meta["choices"] else name.upper())
        if not meta["everyday"]:
            advanced(action)


def advanced(action: argparse.Action) -> argparse.Action:
    """Hide ``action`` from ``--help``; ``--help-all`` shows it (:class:`HelpAll`)."""
    action.full_help = action.help  # type: ignore[attr-defined]
    action.help = argparse.SUPPRESS
    return action


class HelpAll(argparse.Action):
    """``--help-all``: the command's help with every option, the advanced ones too, then exit."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, default: Any = argparse.SUPPRESS,
                 help: str = "show every option, the advanced ones too, and exit") -> None:
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        for action in parser._actions:
            if hasattr(action, "full_help"):
                action.help = action.full_help
        parser.print_help()
        parser.exit()


def _belongs(path: tuple[str, ...], top: str) -> str:
    """Where a setting with section ``path`` goes in a file whose settings table is ``top``."""
    if not path:
        return "at the top level" if not top else f"directly in [{top}]"
    return f"in [{'.'.join((top, *path) if top else path)}]"


def _entries(path: Path, cls: type, data: dict, top: str) -> list[tuple[str, Any, str]]:
    """(key, value, where) of every setting of ``data`` (the top level, or the ``[top]`` table)
    with its section tables opened; ConfigError for a key in a section table not its own."""
    known, alias = leaves(cls), aliases(cls)
    sections = {f.name for f in fields(cls) if "section" in f.metadata}
    here = "at the top level" if not top else f"in [{top}]"
    out: list[tuple[str, Any, str]] = []
    for key, value in data.items():
        if key not in sections or not isinstance(value, dict):
            out.append((key, value, here))
            continue
        table = f"{top}.{key}" if top else key
        for sub, sub_value in value.items():
            name = alias.get(sub.replace("-", "_"), sub.replace("-", "_"))
            if name in known and known[name][0][:1] != (key,):
                raise ConfigError(f"config file {path}: key {sub!r} in table [{table}] is not a {key} setting; "
                                  f"it belongs {_belongs(known[name][0], top)}")
            out.append((sub, sub_value, f"in [{table}]"))
    return out


def read_toml(path: str | Path, cls: type) -> dict:
    """The settings of a TOML file: its top level and a ``[swarmpose]`` table, each with section
    tables (``[tracker]``, ``[swarmpose.zenoh]``, ...). ConfigError naming the file for an
    unknown key, a setting given twice or a key in a section table it does not belong to."""
    path = Path(path).expanduser()
    data = read_toml_file(path, ConfigError, "config file", "pass an existing TOML file to --config")
    inner = data.pop("swarmpose", {})
    if not isinstance(inner, dict):
        raise ConfigError(f"config file {path}: swarmpose must be a table ([swarmpose]), got {inner!r}")
    known, alias = leaves(cls), aliases(cls)
    settings: dict[str, Any] = {}
    given: dict[str, str] = {}
    for key, value, where in _entries(path, cls, data, "") + _entries(path, cls, inner, "swarmpose"):
        name = key.replace("-", "_")
        name = alias.get(name, name)
        if name not in known:
            raise ConfigError(f"config file {path}: unknown key {key!r}; keys are {', '.join(sorted(known))}")
        if name in given:
            raise ConfigError(f"config file {path}: {name} is given twice ({given[name]} and {key!r} {where}); "
                              "keep one")
        given[name] = f"{key!r} {where}"
        settings[name] = convert(name, known[name][1].metadata["kind"], value, f"config file {path}")
    return settings


def from_environment(env: Mapping[str, str], cls: type) -> dict:
    """The settings of ``SWARMPOSE_<NAME>`` variables (current names win over older ones)."""
    known, settings = leaves(cls), {}
    for var, name in sorted(environment_names(cls).items(), key=lambda kv: kv[0] == ENV_PREFIX + kv[1].upper()):
        if var in env:
            settings[name] = convert(name, known[name][1].metadata["kind"], env[var], f"environment variable {var}")
    return settings


def load(cls: type[T], flags: Mapping[str, Any] | None = None, config_file: str | None = None,
         env: Mapping[str, str] | None = None, defaults: Mapping[str, Any] | None = None) -> T:
    """``defaults`` < ``config_file`` (or ``$SWARMPOSE_CONFIG``) < environment < ``flags``
    (setting name -> value; None = not given)."""
    env = os.environ if env is None else env
    known = leaves(cls)
    settings: dict[str, Any] = dict(defaults or {})
    origins: dict[str, str] = {}
    path = config_file or env.get(ENV_CONFIG)
    if path:
        from_file = read_toml(path, cls)
        settings.update(from_file)
        origins.update({name: f"config file {path}" for name in from_file})
    from_env = from_environment(env, cls)
    settings.update(from_env)
    read = {name: var for var, name in environment_names(cls).items() if var in env}  # older names first
    read.update({name: var for var, name in environment_names(cls).items()
                 if var in env and var == ENV_PREFIX + name.upper()})
    origins.update({name: f"environment variable {read[name]}" for name in from_env})
    for name, value in (flags or {}).items():
        if value is None:
            continue
        if name not in known:
            raise ConfigError(f"unknown setting {name!r}")
        origin = f"flag --{name.replace('_', '-')}"
        settings[name] = convert(name, known[name][1].metadata["kind"], value, origin)
        origins[name] = origin
    try:
        return build(cls, settings)
    except ConfigError as exc:
        text = str(exc)
        culprit = next((n for n in origins if text.startswith(n) or text.startswith(n.replace("_", " "))
                        or (text.startswith("camera id") and n == "camera_id")), None)
        raise ConfigError(f"{origins[culprit]}: {text}" if culprit else text) from None


def from_args(cls: type[T], args: argparse.Namespace, defaults: Mapping[str, Any] | None = None) -> T:
    """Settings of parsed flags (those ``add_flags`` made) over the environment, file and defaults."""
    flags = {name: getattr(args, name) for name in leaves(cls) if hasattr(args, name)}
    return load(cls, flags, config_file=getattr(args, "config_file", None), defaults=defaults)
