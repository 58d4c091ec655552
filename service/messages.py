"""The messages of the protocol (``protocol/*.schema.json``): building and validating them.

Three JSON messages, each with ``schema`` (its name) and ``version``:

* ``swarmpose.frame`` — one processed frame with every tracked body (:func:`frame_message`);
* ``swarmpose.status`` — the worker's health, about once a second (built by the worker);
* ``swarmpose.info`` — what a worker tracks and how to read it (:func:`info_message`).

Key expressions for camera ``<camera>``: :func:`keys`. Units: metres (camera frame, OpenCV
axes), pixels, nanoseconds, milliseconds for durations, radians for angles.
"""

from __future__ import annotations

import functools
import json
import platform
import re
from importlib import metadata, resources

import numpy as np

from . import __version__
from .errors import ConfigError, ProtocolError
from .model.skeleton import ANGLE_LIMITS, ANGLE_NAMES, EVAL_JOINTS, EVAL_LINKS
from .tracker import TrackResult, json_vector

PROTOCOL_VERSION = 1
SCHEMAS = ("frame", "status", "info")
CAMERA_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
POSE_NAMES: tuple[str, ...] = ("tx", "ty", "tz", "qw", "qx", "qy", "qz") + ANGLE_NAMES
"""Names of the 36 entries of the pose vector h."""


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
def _validator(name: str):
    import jsonschema

    return jsonschema.Draft202012Validator(schema(name))


def validate(message: dict) -> dict:
    """``message`` if it matches the schema its ``schema`` field names, else a ProtocolError
    saying which field is wrong."""
    name = message.get("schema", "") if isinstance(message, dict) else ""
    kind = name.removeprefix("swarmpose.")
    if kind not in SCHEMAS:
        raise ProtocolError(f"not a swarmpose message: schema {name!r} (expected swarmpose.frame/status/info)")
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


def body_entry(result: TrackResult, body_id: int = 0) -> dict:
    """One body of a frame message from the tracker's answer."""
    joints = {name: {"position_m": json_vector(p3, 6), "pixel": json_vector(p2, 2),
                     "confidence": round(float(np.clip(c, 0.0, 1.0)), 3)}
              for name, p3, p2, c in zip(EVAL_JOINTS, result.joints3d, result.joints2d, result.confidence)}
    return {"id": body_id, "state": result.state, "reason": result.reason,
            "pose": None if result.pose is None else [round(float(x), 6) for x in result.pose],
            "joints": joints,
            "objective": {k: round(float(v), 4) for k, v in result.objective.items() if np.isfinite(v)}}


def frame_message(camera: str, frame: int, capture_ns: int, received_ns: int, publish_ns: int,
                  bodies: list[dict], reason: str = "", timings_ms: dict[str, float] | None = None) -> dict:
    """A ``swarmpose.frame`` message (see ``protocol/frame.schema.json``)."""
    message = {"schema": "swarmpose.frame", "version": PROTOCOL_VERSION, "camera": camera, "frame": int(frame),
               "capture_ns": int(capture_ns), "received_ns": int(received_ns), "publish_ns": int(publish_ns),
               "latency_ms": round(max(publish_ns - received_ns, 0) / 1e6, 3), "reason": reason, "bodies": bodies}
    if timings_ms:
        message["timings_ms"] = {k: round(float(v), 2) for k, v in timings_ms.items()}
    return message


def versions() -> dict[str, str]:
    """Versions of swarmpose, the protocol, zenoh and Python."""
    try:
        zenoh_version = metadata.version("eclipse-zenoh")
    except metadata.PackageNotFoundError:
        zenoh_version = "not installed"
    return {"swarmpose": __version__, "protocol": str(PROTOCOL_VERSION), "zenoh": zenoh_version,
            "python": platform.python_version()}


def info_message(camera: str, *, intrinsics=None, body=None, body_spec: str = "", source: str = "",
                 detector: str = "", mode: str = "hybrid", opencl_device: str = "") -> dict:
    """A ``swarmpose.info`` message. intrinsics: :class:`~swarmpose.camera.Intrinsics` or None
    (no frame yet); body: the tracking :class:`~swarmpose.model.body.SkinnedBody`."""
    intr = None if intrinsics is None else {
        "width": int(intrinsics.width), "height": int(intrinsics.height), "fx": float(intrinsics.fx),
        "fy": float(intrinsics.fy), "cx": float(intrinsics.cx), "cy": float(intrinsics.cy)}
    body_info = {"spec": body_spec, "name": getattr(body, "name", ""),
                 "height_m": round(float(body.height), 4) if body is not None else 0.0,
                 "bones": len(body.bone_names) if body is not None else 0,
                 "triangles": len(body.triangles) if body is not None else 0}
    limits = {n: [float(lo), float(hi)] for n, (lo, hi) in zip(ANGLE_NAMES, ANGLE_LIMITS)}
    return {"schema": "swarmpose.info", "version": PROTOCOL_VERSION, "camera": camera, "keys": keys(camera),
            "skeleton": {"joints": list(EVAL_JOINTS), "links": [list(link) for link in EVAL_LINKS], "units": "m",
                         "frame": "camera (OpenCV: x right, y down, z forward)"},
            "pose_vector": {"names": list(POSE_NAMES), "limits_rad": limits},
            "intrinsics": intr, "body": body_info, "source": source, "detector": detector, "mode": mode,
            "opencl_device": opencl_device, "versions": versions()}
