"""Several people in one synthetic scene: who they are, where they start, how the camera films them.

A person is given on the command line as ``--person BODY:SHAPE:MOTION[@x,z[,yaw[,start]]]``:

* ``BODY`` is ``builtin``, ``makehuman:DIR`` (the next ``:``-field is the directory) or a
  ``.glb`` / ``.gltf`` path; ``SHAPE`` a shape of that body (empty = its default);
  ``MOTION`` a BVH path or ``builtin:NAME``. A directory or path holding ``:`` cannot be
  written this way: use a scene file.
* ``@x,z`` (metres, world frame) is where the person's root starts on the floor (default
  ``0,0``; with ``--camera-yaw 0``, x grows to the image's right and z towards the
  camera); ``yaw`` (degrees) turns the person's whole motion about the vertical: +90
  turns a clip walking towards the camera (``--camera-yaw 0``) into one walking to the
  image's right; ``start`` (seconds) skips the clip's beginning, so a start-walk-stop clip
  can begin mid-stride. The placement follows the *last* ``@``; a path holding ``@``
  needs an explicit placement after it. (``@``, not ``:``, because ``makehuman:DIR``
  already uses ``:``.)

A scene file (``--scene FILE``) is a JSON list of objects with keys ``body``, ``shape``,
``motion`` (required), ``x``, ``z``, ``yaw`` (degrees) and ``start`` (seconds), the same
fields without parsing; or an object ``{"people": [that list], "props": ["stool", ...]}``
whose props are written as ``--prop`` takes them (:mod:`swarmpose.sim.props`).

World frame (as :mod:`swarmpose.motion.sequence`): X = a person's left at the first frame
when yaw = 0, Y = up, Z = forward, floor at y = 0. The camera stands ``camera_distance``
in front of the scene centre (the mean of the start positions), turned ``camera_yaw``
about the vertical, its lens ``camera_height`` above the floor, looking at the middle of
the people; the back wall stands 2 m behind the farthest start (and at least 0.5 m behind
every root position of the sequence).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmpose.body.kinematics import axis_angle_matrix, matrix_to_quaternion
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import POSE_DIM
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import look_at
from swarmpose.core.errors import ConfigError, SwarmposeError
from swarmpose.motion.library import load_motion_spec
from swarmpose.motion.sequence import Motion
from swarmpose.sim.props import PROP_HELP, PropSpec, parse_prop_spec
from swarmpose.sim.render import PERSON_ALBEDOS, Room

MAX_PEOPLE = len(PERSON_ALBEDOS)
"""At most this many people in a scene (one distinct clothing colour each)."""
MIN_START_GAP = 0.3
"""Two people's start positions closer than this (m) would stand inside each other."""
MAX_START_DISTANCE = 20.0
"""|x| and |z| of a start position stay within this (m)."""
WALL_BEHIND_SUBJECT = 2.0
"""The back wall stands this far (m) behind the farthest start position..."""
WALL_BEHIND_ANY_ROOT = 0.5
"""...and at least this far (m) behind every root position of the sequence."""

SPEC_HELP = ("write --person BODY:SHAPE:MOTION[@x,z[,yaw[,start]]], e.g. builtin:female:builtin:walk@0.5,-1,90 or "
             "makehuman:DIR:male:clip.bvh@-1,0 (SHAPE may be empty: builtin::builtin:wave)")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_PLACEMENT = re.compile(rf"^\s*({_NUMBER})\s*,\s*({_NUMBER})\s*(?:,\s*({_NUMBER})\s*)?(?:,\s*({_NUMBER})\s*)?$")
_SCENE_KEYS = {"body", "shape", "motion", "x", "z", "yaw", "start"}


@dataclass(frozen=True)
class PersonSpec:
    """One person of a scene, as written: body and shape specs (:func:`load_body`), motion spec
    (:func:`load_motion_spec`), start position x, z (m, world frame), yaw (degrees) and the
    seconds of the clip skipped before the first frame."""

    body: str = "builtin"
    shape: str | None = None
    motion: str = "builtin:wave"
    x: float = 0.0
    z: float = 0.0
    yaw_deg: float = 0.0
    start_s: float = 0.0

    def as_dict(self) -> dict:
        """The fields ``sequence.json`` lists (and a scene file takes)."""
        return {"body": self.body, "shape": self.shape, "motion": self.motion,
                "x": self.x, "z": self.z, "yaw": self.yaw_deg, "start": self.start_s}


def parse_person_spec(text: str) -> PersonSpec:
    """``BODY:SHAPE:MOTION[@x,z[,yaw[,start]]]`` -> :class:`PersonSpec`; ConfigError names the spec."""
    head, x, z, yaw, start = text, 0.0, 0.0, 0.0, 0.0
    if "@" in text:
        head, _, placement = text.rpartition("@")
        match = _PLACEMENT.match(placement)
        if not match:
            raise ConfigError(f"--person {text!r}: the placement after '@' must be x,z or x,z,yaw or "
                              f"x,z,yaw,start (metres, degrees, seconds), got {placement!r}; {SPEC_HELP}")
        x, z = float(match.group(1)), float(match.group(2))
        yaw, start = (float(g) if g is not None else 0.0 for g in match.group(3, 4))
    fields = head.split(":")
    if fields[0] == "makehuman":
        if len(fields) < 4 or not fields[1]:
            raise ConfigError(f"--person {text!r}: makehuman needs its directory, a shape and a motion; {SPEC_HELP}")
        body, rest = f"makehuman:{fields[1]}", fields[2:]
    else:
        body, rest = fields[0], fields[1:]
    if len(rest) < 2:
        raise ConfigError(f"--person {text!r} has no motion; {SPEC_HELP}")
    shape, motion = rest[0], ":".join(rest[1:])
    return _checked(PersonSpec(body, shape or None, motion, x, z, yaw, start), f"--person {text!r}")


def load_scene_file(path: Path) -> list[PersonSpec]:
    """A scene file (JSON list of {body, shape, motion, x, z, yaw, start}) -> its people; ConfigError
    names the file and the entry."""
    return read_scene_file(path)[0]


def read_scene_file(path: Path) -> tuple[list[PersonSpec], list[PropSpec]]:
    """A scene file -> its people and props: a JSON list of people {body, shape, motion, x, z, yaw,
    start}, or an object {"people": [that list], "props": [prop specs as --prop takes them]};
    ConfigError names the file and the entry."""
    path = Path(path).expanduser()
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"--scene {path}: cannot read it ({exc.strerror or exc}); "
                          "give an existing JSON file") from None
    except ValueError as exc:
        raise ConfigError(f"--scene {path}: not JSON ({exc}); write a list of "
                          '{"body", "shape", "motion", "x", "z", "yaw", "start"} objects') from None
    props = []
    if isinstance(data, dict):
        unknown = set(data) - {"people", "props"}
        if unknown:
            raise ConfigError(f"--scene {path}: unknown keys {sorted(unknown)}; a scene object holds 'people' "
                              "and 'props'")
        extra = data.get("props", [])
        if not isinstance(extra, list):
            raise ConfigError(f"--scene {path}: 'props' must be a list of prop specs; {PROP_HELP}")
        props = [parse_prop_spec(text, f"--scene {path}, prop {k}") for k, text in enumerate(extra, 1)]
        data = data.get("people")
    if not isinstance(data, list) or not data:
        raise ConfigError(f"--scene {path}: expected a non-empty JSON list of people, got {type(data).__name__}")
    people = []
    for k, entry in enumerate(data, 1):
        where = f"--scene {path}, person {k}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: expected an object with body, shape, motion, x, z, yaw, start")
        unknown = set(entry) - _SCENE_KEYS
        if unknown:
            raise ConfigError(f"{where}: unknown keys {sorted(unknown)}; use {sorted(_SCENE_KEYS)}")
        if not isinstance(entry.get("motion"), str) or not entry["motion"]:
            raise ConfigError(f"{where}: 'motion' (a BVH path or builtin:NAME) is required")
        for key in ("body", "shape"):
            if entry.get(key) is not None and not isinstance(entry[key], str):
                raise ConfigError(f"{where}: {key!r} must be a string, got {entry[key]!r}")
        numbers = {}
        for key in ("x", "z", "yaw", "start"):
            value = entry.get(key, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"{where}: {key!r} must be a number, got {value!r}")
            numbers[key] = float(value)
        people.append(_checked(PersonSpec(entry.get("body") or "builtin", entry.get("shape") or None,
                                          entry["motion"], numbers["x"], numbers["z"], numbers["yaw"],
                                          numbers["start"]), where))
    return people, props


def _checked(spec: PersonSpec, where: str) -> PersonSpec:
    if not (spec.body == "builtin" or spec.body.startswith("makehuman:")
            or spec.body.lower().endswith((".glb", ".gltf"))):
        raise ConfigError(f"{where}: unknown body {spec.body!r}; use builtin, makehuman:DIR or a .glb/.gltf file")
    if not spec.motion:
        raise ConfigError(f"{where}: empty motion; give a BVH path or builtin:NAME")
    for name, value in (("x", spec.x), ("z", spec.z)):
        if not (math.isfinite(value) and abs(value) <= MAX_START_DISTANCE):
            raise ConfigError(f"{where}: start {name} = {value} m; keep it within ±{MAX_START_DISTANCE:g} m")
    if not math.isfinite(spec.yaw_deg):
        raise ConfigError(f"{where}: yaw must be a finite number of degrees, got {spec.yaw_deg}")
    if not (math.isfinite(spec.start_s) and spec.start_s >= 0):
        raise ConfigError(f"{where}: start must be a non-negative number of seconds, got {spec.start_s}")
    return spec


def check_scene(specs: Sequence[PersonSpec]) -> None:
    """ConfigError unless the scene has 1..MAX_PEOPLE people whose starts are apart."""
    if not 1 <= len(specs) <= MAX_PEOPLE:
        raise ConfigError(f"a scene holds 1 to {MAX_PEOPLE} people, got {len(specs)}; give fewer --person")
    for a in range(len(specs)):
        for b in range(a + 1, len(specs)):
            gap = math.hypot(specs[a].x - specs[b].x, specs[a].z - specs[b].z)
            if gap < MIN_START_GAP:
                raise ConfigError(f"people {a + 1} and {b + 1} start {gap:.2f} m apart and would stand inside "
                                  f"each other; give them start positions at least {MIN_START_GAP} m apart (@x,z)")


@dataclass(frozen=True)
class ScenePerson:
    """A loaded person: its spec, body and motion."""

    spec: PersonSpec
    body: SkinnedBody
    motion: Motion


def load_people(specs: Sequence[PersonSpec], frames: int, fps: float) -> list[ScenePerson]:
    """Load each spec's body and motion (``frames`` frames at ``fps`` from the spec's start);
    errors name the person."""
    check_scene(specs)
    people = []
    for k, spec in enumerate(specs, 1):
        skip = int(round(spec.start_s * fps))
        try:
            body = load_body(spec.body, spec.shape)
            motion = load_motion_spec(spec.motion, body, frames + skip, fps)
        except SwarmposeError as exc:
            raise type(exc)(f"person {k} ({spec.body}:{spec.shape or ''}:{spec.motion}): {exc}") from exc
        if len(motion) < frames + skip:
            raise ConfigError(f"person {k}: motion {motion.name!r} has {len(motion)} frames at {motion.fps:g} fps, "
                              f"{skip} skipped by start {spec.start_s:g} s; ask for --frames "
                              f"{max(len(motion) - skip, 0)} or fewer, or an earlier start")
        if skip:
            motion = Motion(motion.name, motion.fps, motion.root_offset[skip:], motion.root_rotation[skip:],
                            motion.angles[skip:])
        people.append(ScenePerson(spec, body, motion))
    return people


@dataclass(frozen=True)
class SceneFilming:
    """poses: per person (N, 36) camera-frame poses; rotation: world -> camera (3, 3); eye: (3,)
    world m; room: floor, wall and props in the camera frame; starts: (P, 3) world root positions
    at the first frame; props: the props in the world frame (:class:`swarmpose.sim.props.Prop`)."""

    poses: tuple[np.ndarray, ...]
    rotation: np.ndarray
    eye: np.ndarray
    room: Room
    starts: np.ndarray
    props: tuple = ()


@dataclass(frozen=True)
class PlacedPerson:
    """A body and its world-frame motion: poses (N, 36) and root rotations (N, 3, 3) body -> world."""

    body: SkinnedBody
    poses: np.ndarray
    rotations: np.ndarray


def place_in_world(body: SkinnedBody, motion: Motion, frames: int, x: float = 0.0, z: float = 0.0,
                   yaw_deg: float = 0.0, skinning: str = "dqs") -> PlacedPerson:
    """The first ``frames`` frames of ``motion`` on ``body`` in the world frame: the root starts
    above (x, z), the whole motion turned ``yaw_deg`` about the vertical, the lowest sole of the
    whole sequence on the floor."""
    n = min(len(motion), frames)
    offset = motion.root_offset[:n]
    rot = motion.root_rotation[:n]
    first = motion.root_offset[0] * np.array([1.0, 0.0, 1.0])
    if np.any(first != 0):
        offset = offset - first  # the root starts exactly above (x, z)
    if yaw_deg != 0:
        turn = axis_angle_matrix((0.0, 1.0, 0.0), np.radians(yaw_deg))
        offset = offset @ turn.T
        rot = turn @ rot
    world = np.zeros((n, POSE_DIM))
    world[:, 0:3] = np.array([x, body.floor_offset, z]) + offset
    world[:, 3:7] = matrix_to_quaternion(rot)
    world[:, 7:] = motion.angles[:n]
    lowest = min(float(body.pose(world[i:i + 64], skinning)[..., 1].min()) for i in range(0, n, 64))
    world[:, 1] -= lowest  # the lowest sole of the whole sequence touches the floor
    return PlacedPerson(body, world, rot)


def place_people(people: Sequence[PlacedPerson], camera_distance: float, camera_yaw_deg: float,
                 camera_height: float) -> SceneFilming:
    """Film people placed in the world: the camera ``camera_distance`` m in front of the scene
    centre, turned ``camera_yaw_deg`` about it, ``camera_height`` m up; the room around them;
    every pose in the camera frame."""
    starts = np.stack([p.poses[0, 0:3] for p in people])
    centre = np.mean(starts, axis=0)
    yaw = np.radians(camera_yaw_deg)
    eye = np.array([centre[0] + camera_distance * np.sin(yaw), camera_height,
                    centre[2] + camera_distance * np.cos(yaw)])
    target = np.array([centre[0], 0.5 * float(np.mean([p.body.height for p in people])), centre[2]])
    r_cw = look_at(eye, target)
    ahead = target - eye
    ahead[1] = 0.0
    ahead /= np.linalg.norm(ahead)
    behind_centre = max(float((s - centre) @ ahead) for s in starts)
    farthest_root = max(float(np.max((p.poses[:, 0:3] - eye) @ ahead)) for p in people)
    wall_distance = max(camera_distance + behind_centre + WALL_BEHIND_SUBJECT, farthest_root + WALL_BEHIND_ANY_ROOT)
    wall = eye + ahead * wall_distance
    poses = []
    for person in people:
        cam = person.poses.copy()
        cam[:, 0:3] = (person.poses[:, 0:3] - eye) @ r_cw.T
        cam[:, 3:7] = matrix_to_quaternion(r_cw @ person.rotations)
        poses.append(cam)
    room = Room(floor_point=r_cw @ (np.zeros(3) - eye), floor_normal=r_cw @ np.array([0.0, 1.0, 0.0]),
                wall_point=r_cw @ (wall - eye), wall_normal=r_cw @ -ahead)
    return SceneFilming(tuple(poses), r_cw, eye, room, starts)
