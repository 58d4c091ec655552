"""The one exception hierarchy of swarmpose.

Every error raised on purpose derives from :class:`SwarmposeError`. Messages say what
was wrong (naming the input) and what to do about it; the CLI prints them on one line
and exits with status 2.
"""

from __future__ import annotations


class SwarmposeError(Exception):
    """Base class of every error swarmpose raises on purpose."""


class ConfigError(SwarmposeError):
    """A flag, option or configuration value is invalid."""


class AssetError(SwarmposeError):
    """A body model, rig, target or motion file is missing or malformed."""


class MotionError(AssetError):
    """A motion-capture file cannot be read or retargeted."""


class ShapeError(SwarmposeError, ValueError):
    """An array has the wrong shape or dtype; the message carries both shapes."""


class OutputError(SwarmposeError):
    """An output location cannot be created or written."""


def check_shape(name: str, array, expected: tuple) -> None:
    """Raise :class:`ShapeError` unless ``array.shape`` matches ``expected``.

    ``expected`` may hold ``None`` for any size along that axis, e.g. ``(None, 3)``.
    """
    shape = tuple(getattr(array, "shape", ()))
    ok = len(shape) == len(expected) and all(e is None or e == s for s, e in zip(shape, expected))
    if not ok:
        pretty = "(" + ", ".join("N" if e is None else str(e) for e in expected) + ")"
        raise ShapeError(f"{name} has shape {shape}, expected {pretty}")


class SourceError(SwarmposeError):
    """A frame source (camera, recording, folder) cannot be opened or read."""


class DetectorError(SwarmposeError):
    """A 2D joint detector cannot be built or fails on a frame."""


class TrackingError(SwarmposeError):
    """The tracker was given inputs it cannot work with (e.g. an observation of the wrong size)."""


class ProtocolError(SwarmposeError):
    """A message does not follow the protocol (not JSON, or not matching its schema)."""


class PublishError(SwarmposeError):
    """zenoh could not be opened or configured (bad endpoint, port taken)."""


class PersonalisationError(SwarmposeError):
    """A body's shape could not be estimated from the recording (no person, too few frames)."""
