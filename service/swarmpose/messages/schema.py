"""The wire side of the protocol: key expressions, JSON Schemas, validation, encoding.

Every message is a JSON object with ``schema`` (``swarmpose.frame``, ``swarmpose.status``
or ``swarmpose.info``) and ``version``; ``protocol/*.schema.json`` (shipped as the
``swarmpose.protocol`` package data) define them.
"""

from __future__ import annotations

import functools
import json
import re
from importlib import resources
from typing import TYPE_CHECKING

from swarmpose.core.errors import ConfigError, ProtocolError

if TYPE_CHECKING:  # jsonschema is imported by the first validation
    import jsonschema

PROTOCOL_VERSION = 7
"""The protocol as a whole; raised whenever one message's version is."""
MESSAGE_VERSIONS = {"frame": 5, "status": 3, "info": 4}
"""Each message's own version: frame 2 added the optional per-body ``detection``; status 2 the
optional ``tracker.people`` counts; status 3 and info 2 the optional ``personalisation``
(``tracker.personalisation``, ``body.personalisation``: ``--personalize N``); frame 3 and info 3
the world frame (frame ``coordinates`` and ``camera_to_world``, info ``world``: ``--floor``,
``--coordinates``); frame 4 each joint's optional ``velocity_m_s``; frame 5 and info 4 the full
joint set (28 joints, each with ``orientation_xyzw``; info ``skeleton.parents``,
``evaluation_joints`` and ``orientation``)."""
SCHEMAS = ("frame", "status", "info")
CAMERA_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def check_camera_id(camera: str) -> str:
    """``camera`` if it can be one chunk of a zenoh key expression, else a ConfigError."""
    if not isinstance(camera, str) or not CAMERA_ID.match(camera):
        raise ConfigError(f"camera id {camera!r} must be 1-64 letters, digits, '_', '-' or '.' "
                          "(it becomes part of the zenoh key swarmpose/<camera>/...); e.g. --camera-id kinect0")
    return camera


def keys(camera: str) -> dict[str, str]:
    """The zenoh key expressions of camera ``camera`` (``*`` for every camera)."""
    return {kind: f"swarmpose/{camera}/{kind}" for kind in ("frame", "status", "alive", "info")}


@functools.cache
def schema(name: str) -> dict:
    """The JSON Schema of message ``name`` (frame, status or info)."""
    if name not in SCHEMAS:
        raise ConfigError(f"no schema {name!r}; the protocol has {SCHEMAS}")
    return json.loads(resources.files("swarmpose.protocol").joinpath(f"{name}.schema.json").read_text("utf-8"))


@functools.cache
def _validator(name: str) -> jsonschema.Draft202012Validator:
    import jsonschema

    return jsonschema.Draft202012Validator(schema(name))


def validate(message: dict) -> dict:
    """``message`` if it matches the schema its ``schema`` field names, else a ProtocolError
    saying which field is wrong (a version other than :data:`MESSAGE_VERSIONS`' first of all)."""
    name = message.get("schema", "") if isinstance(message, dict) else ""
    kind = name.removeprefix("swarmpose.")
    if kind not in SCHEMAS:
        raise ProtocolError(f"not a swarmpose message: schema {name!r} (expected swarmpose.frame/status/info)")
    version = message.get("version")
    if version != MESSAGE_VERSIONS[kind]:  # said first: an older or newer peer, not a broken message
        raise ProtocolError(f"{name} message invalid at version: {version!r}, while this swarmpose reads version "
                            f"{MESSAGE_VERSIONS[kind]} (protocol {PROTOCOL_VERSION}); run the same swarmpose version "
                            "on both sides (protocol/README.md, Versioning)")
    errors = sorted(_validator(kind).iter_errors(message), key=lambda e: list(e.absolute_path))
    if errors:
        first = errors[0]
        where = "/".join(str(p) for p in first.absolute_path) or "(top level)"
        raise ProtocolError(f"{name} message invalid at {where}: {first.message}"
                            + (f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""))
    return message


def decode(payload: bytes | str) -> dict:
    """Parse one JSON message; a ProtocolError names what is wrong with it."""
    try:
        message = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"message is not JSON: {exc}") from exc
    if not isinstance(message, dict):
        raise ProtocolError(f"message is a JSON {type(message).__name__}, expected an object")
    return message


def encode(message: dict) -> bytes:
    """Compact UTF-8 JSON (NaN is not JSON: numbers must be finite, unknowns null)."""
    return json.dumps(message, allow_nan=False, separators=(",", ":")).encode("utf-8")
