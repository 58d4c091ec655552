"""A motion by its spec: ``builtin:NAME`` (a procedural motion) or a BVH file retargeted onto a body.

A BVH spec may end in options, ``FILE.bvh?map=names.toml&units=cm&up=z``: ``map`` a joint map
(:mod:`swarmpose.motion.joint_map`; a path as typed, from the working directory), ``units`` and
``up`` the file's length unit and up axis (:mod:`swarmpose.motion.clip_frame`), which override
the map file's. Without them the family is recognised by its joint names and units and up axis
are detected.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qsl

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import MotionError
from swarmpose.motion.builtin import builtin_motion
from swarmpose.motion.clip_frame import parse_units, parse_up
from swarmpose.motion.joint_map import read_joint_map
from swarmpose.motion.retarget import ReadOptions, load_motion
from swarmpose.motion.sequence import Motion

OPTION_KEYS = ("map", "units", "up")


def split_motion_spec(spec: str) -> tuple[str, ReadOptions]:
    """``FILE.bvh[?map=M&units=U&up=A]`` -> the file's path and how to read it.

    A spec that names an existing file as a whole is a path (even with a '?'). Raises
    MotionError naming the spec for an unknown or repeated option or a bad unit or axis, and
    for a map file that cannot be read.
    """
    if "?" not in spec or Path(spec).expanduser().exists():
        return spec, ReadOptions()
    path, query = spec.rsplit("?", 1)
    where = f"--motion {spec}"
    pairs = parse_qsl(query, keep_blank_values=True)
    keys = [k for k, _ in pairs]
    bad = [k for k in keys if k not in OPTION_KEYS] or [k for k in set(keys) if keys.count(k) > 1]
    if bad or not pairs:
        raise MotionError(f"{where}: options after '?' are map=FILE.toml, units=UNIT and up=AXIS, each once, "
                          f"joined by '&' (found {query!r})")
    options = dict(pairs)
    empty = [k for k, v in options.items() if not v]
    if empty:
        raise MotionError(f"{where}: {', '.join(empty)} has no value; write e.g. ?map=names.toml&units=cm&up=z")
    return path, ReadOptions(
        joint_map=read_joint_map(options["map"]) if "map" in options else None,
        units=parse_units(options["units"], where) if "units" in options else None,
        up=parse_up(options["up"], where) if "up" in options else None)


def load_motion_spec(spec: str, body: SkinnedBody, frames: int, fps: float) -> Motion:
    """``builtin:NAME`` -> ``frames`` frames of a procedural motion at ``fps``; anything else is a
    BVH file (with options, see :func:`split_motion_spec`) retargeted onto ``body`` and resampled
    to ``fps``."""
    if spec.startswith("builtin:"):
        return builtin_motion(spec.split(":", 1)[1], frames, fps)
    path, options = split_motion_spec(spec)
    return load_motion(str(Path(path).expanduser()), body, fps, options)
