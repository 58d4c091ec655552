"""A motion by its spec: ``builtin:NAME`` (a procedural motion) or a BVH file retargeted onto a body.

A BVH spec may end in options, ``FILE.bvh?map=names.toml&units=cm&up=z``: ``map`` a joint map
(:mod:`swarmpose.motion.joint_map`; a path as typed, from the working directory), ``units`` and
``up`` the file's length unit and up axis (:mod:`swarmpose.motion.clip_frame`), which override
the map file's. Without them the family is recognised by its joint names and units and up axis
are detected.

Any motion spec, a BVH file's or a built-in's, may hold a frame: ``?hold=SECONDS`` or
``?hold=AT:SECONDS`` (:mod:`swarmpose.motion.hold`), e.g. ``clip.bvh?units=cm&hold=1.5:3`` or
``builtin:walk?hold=3``.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qsl

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import MotionError
from swarmpose.motion.builtin import builtin_motion
from swarmpose.motion.clip_frame import parse_units, parse_up
from swarmpose.motion.hold import Hold, hold_motion, motion_frames_needed, parse_hold
from swarmpose.motion.joint_map import read_joint_map
from swarmpose.motion.retarget import ReadOptions, load_motion
from swarmpose.motion.sequence import Motion

OPTION_KEYS = ("map", "units", "up")


def split_motion_spec(spec: str) -> tuple[str, ReadOptions]:
    """``FILE.bvh[?map=M&units=U&up=A]`` -> the file's path and how to read it (a ``hold=`` is
    :func:`split_hold`'s, and left out here).

    A spec that names an existing file as a whole is a path (even with a '?'). Raises
    MotionError naming the spec for an unknown or repeated option or a bad unit or axis, and
    for a map file that cannot be read.
    """
    where = f"--motion {spec}"
    spec = split_hold(spec)[0]
    if "?" not in spec or Path(spec).expanduser().exists():
        return spec, ReadOptions()
    path, query = spec.rsplit("?", 1)
    pairs = parse_qsl(query, keep_blank_values=True)
    keys = [k for k, _ in pairs]
    bad = [k for k in keys if k not in OPTION_KEYS] or [k for k in set(keys) if keys.count(k) > 1]
    if bad or not pairs:
        raise MotionError(f"{where}: options after '?' are map=FILE.toml, units=UNIT, up=AXIS and "
                          f"hold=[AT:]SECONDS, each once, joined by '&' (found {query!r})")
    options = dict(pairs)
    empty = [k for k, v in options.items() if not v]
    if empty:
        raise MotionError(f"{where}: {', '.join(empty)} has no value; write e.g. ?map=names.toml&units=cm&up=z")
    return path, ReadOptions(
        joint_map=read_joint_map(options["map"]) if "map" in options else None,
        units=parse_units(options["units"], where) if "units" in options else None,
        up=parse_up(options["up"], where) if "up" in options else None)


def split_hold(spec: str) -> tuple[str, Hold | None]:
    """A motion spec without its ``hold=`` option, and the hold (None without one). A spec that
    names an existing file as a whole is a path. MotionError naming the spec for a malformed or
    repeated hold."""
    if "?" not in spec or Path(spec).expanduser().exists():
        return spec, None
    path, query = spec.rsplit("?", 1)
    parts = query.split("&")
    holds = [p.partition("=")[2] for p in parts if p.partition("=")[0] == "hold"]
    if not holds:
        return spec, None
    where = f"--motion {spec}"
    if len(holds) > 1:
        raise MotionError(f"{where}: hold is given {len(holds)} times; give it once")
    rest = "&".join(p for p in parts if p.partition("=")[0] != "hold")
    return (f"{path}?{rest}" if rest else path), parse_hold(holds[0], where)


def load_motion_spec(spec: str, body: SkinnedBody, frames: int, fps: float) -> Motion:
    """``builtin:NAME`` -> ``frames`` frames of a procedural motion at ``fps``; anything else is a
    BVH file (with options, see :func:`split_motion_spec`) retargeted onto ``body`` and resampled
    to ``fps``. Either with ``?hold=`` holds a frame (:func:`split_hold`; a built-in motion is
    then sampled so that the held sequence has ``frames`` frames, or the hold's if more)."""
    plain, hold = split_hold(spec)
    if plain.startswith("builtin:"):
        name = plain.split(":", 1)[1]
        if "?" in name:
            raise MotionError(f"--motion {spec}: a built-in motion takes only ?hold=[AT:]SECONDS "
                              f"(found {name.split('?', 1)[1]!r})")
        needed = frames if hold is None else motion_frames_needed(hold, frames, fps)
        motion = builtin_motion(name, needed, fps)
    else:
        path, options = split_motion_spec(plain)
        motion = load_motion(str(Path(path).expanduser()), body, fps, options)
    return motion if hold is None else hold_motion(motion, hold, f"--motion {spec}")
