"""Props of a synthetic scene: boxes standing on the floor (a stool to sit on, a table that hides
the legs, any box), asked for with ``synth --prop SPEC`` (repeatable) or a scene file's ``props``.

Specs:

* ``stool`` (or ``stool:K`` for person K, default 1): a 0.40 m square box under the person where
  their hips are lowest, turned as the person faces there, its top at the height of the body's
  seat then: the lowest point of the buttocks and thighs (the skin moved by the pelvis and hip
  joints alone) above the stool's footprint. It stands under the mean position of the hips over
  the frames where they are within :data:`SIT_BAND_M` of their lowest. A clip whose hips never
  go below :data:`SIT_SHARE` of their standing height has nobody sitting, and is an error.
* ``table`` (or ``table:K``): a solid box 1.20 m wide, 0.60 m deep and 0.75 m high (a desk with
  a front panel, or a counter) between the camera and person K, across the line from the
  person's lowest hips to the camera, its near side :data:`TABLE_GAP_M` beyond the farthest
  point the person reaches towards the camera in the sequence. Solid rather than a top on four
  legs: a top 0.75 m high hides only a band of the legs from a camera 1.2 m up (the shins show
  between its legs), a solid box hides everything under its top, which is what the legs of a
  person seated behind a desk look like from the front.
* ``box:x,z,w,d,h[,yaw]``: the footprint's centre (x, z) m in the world frame of
  :mod:`swarmpose.sim.scene`, width w (along the box's own x), depth d (its own z) and
  height h m, turned ``yaw`` degrees about the vertical.

A prop is static scenery: it is rendered with the room (depth, its own colour, labelled as no
person), hides the people behind it from the simulated detector as another person would, and is
written to ``sequence.json`` under ``props``: kind, spec, footprint centre, size and yaw in the
world frame, and its centre, axes and corners in the camera frame.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from swarmpose.body.kinematics import axis_angle_matrix
from swarmpose.body.skeleton import JOINT_INDEX
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError
from swarmpose.sim.render import Solid

PROP_HELP = ("write --prop stool, --prop table (stool:K / table:K for person K) or --prop box:x,z,w,d,h[,yaw] "
             "(metres, degrees; e.g. box:0.7,-0.1,0.4,0.4,0.45)")
STOOL_SIZE_M = 0.40
"""Width and depth of an automatic stool's square top (m)."""
TABLE_SIZE_M = (1.20, 0.60, 0.75)
"""Width (across the camera's view), depth and height of an automatic table (m)."""
TABLE_GAP_M = 0.15
"""An automatic table's near side stands this far (m) beyond the farthest named point (toes, knees,
hands) the person reaches towards the camera: the point is a joint centre, the skin lies up to
about 7 cm beyond it."""
TABLE_CAMERA_CLEARANCE_M = 0.3
"""An automatic table's far side stays at least this far (m) from the camera's lens."""
SIT_SHARE = 0.75
"""Hips lower than this share of their standing height count as seated."""
SIT_BAND_M = 0.03
"""The frames where the hips are within this (m) of their lowest place the stool."""
SIZE_RANGE_M = (0.05, 5.0)
"""Each side of an explicit box (m)."""
MAX_PROP_DISTANCE_M = 20.0
"""|x| and |z| of an explicit box's centre (m), as a person's start."""
ALBEDOS = {"stool": np.array([0.45, 0.30, 0.18]), "table": np.array([0.62, 0.50, 0.36]),
           "box": np.array([0.50, 0.53, 0.56])}
"""Each kind's colour (RGB 0..1): wood, light wood, grey; none is a person's colour."""
KINDS = tuple(ALBEDOS)

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_BOX = re.compile(rf"^\s*{_NUMBER}\s*(?:,\s*{_NUMBER}\s*){{4,5}}$")
_TRIANGLES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                       [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], dtype=np.uint32)
"""The 12 triangles of a box whose corners are ordered as :meth:`Prop.corners` gives them (outward,
counter-clockwise seen from outside)."""


@dataclass(frozen=True)
class PropSpec:
    """One prop as asked for: kind (``stool``, ``table`` or ``box``), the person (1-based) an
    automatic one is placed for, a box's x, z, width, depth, height (m) and yaw (degrees) (also
    set on a stool or table placed before, :func:`placed_spec`: it then stands there), and the
    text it was read from."""

    kind: str
    person: int = 1
    box: tuple[float, float, float, float, float, float] | None = None
    text: str = ""


@dataclass(frozen=True)
class Prop:
    """A box standing on the floor, world frame (:mod:`swarmpose.sim.scene`: Y up, floor at y = 0):
    its footprint's centre (x, z) m, width along its own x, depth along its own z and height (m),
    turned ``yaw_deg`` about the vertical (its own z is (sin yaw, 0, cos yaw) in the world)."""

    kind: str
    x: float
    z: float
    width: float
    depth: float
    height: float
    yaw_deg: float = 0.0
    spec: str = ""

    @property
    def rotation(self) -> np.ndarray:
        """Box -> world rotation (3, 3): columns are the box's x, y (up) and z axes."""
        return axis_angle_matrix((0.0, 1.0, 0.0), math.radians(self.yaw_deg))

    def corners(self) -> np.ndarray:
        """The 8 corners (8, 3) m, world frame: the bottom four (y = 0), then the top four, each
        going round as (-x, -z), (+x, -z), (+x, +z), (-x, +z) in the box's own axes."""
        hw, hd = 0.5 * self.width, 0.5 * self.depth
        ring = np.array([[-hw, 0.0, -hd], [hw, 0.0, -hd], [hw, 0.0, hd], [-hw, 0.0, hd]])
        local = np.concatenate([ring, ring + [0.0, self.height, 0.0]])
        return local @ self.rotation.T + [self.x, 0.0, self.z]

    def local(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in the box's own frame (origin at the footprint's centre)."""
        return (np.asarray(points, float) - [self.x, 0.0, self.z]) @ self.rotation

    def solid(self, world_to_camera: np.ndarray, eye: np.ndarray) -> Solid:
        """The box as a mesh in the camera frame of a camera at ``eye`` (3,) world m turned by
        ``world_to_camera`` (3, 3), in its kind's colour."""
        return Solid((self.corners() - eye) @ world_to_camera.T, _TRIANGLES.copy(), ALBEDOS[self.kind])

    def as_dict(self, world_to_camera: np.ndarray, eye: np.ndarray) -> dict:
        """The truth's description: kind, spec, in the world its footprint's centre, size (width,
        height, depth: along the box's x, y, z) and yaw, and in the camera frame its centre (of the
        volume), axes (rows: the box's x, y (up), z) and corners (8, 3, as :meth:`corners`)."""
        centre = np.array([self.x, 0.5 * self.height, self.z])
        return {"kind": self.kind, "spec": self.spec,
                "world": {"centre_floor_m": [round(self.x, 6), 0.0, round(self.z, 6)],
                          "size_m": [round(v, 6) for v in (self.width, self.height, self.depth)],
                          "yaw_deg": round(self.yaw_deg, 4)},
                "camera": {"centre_m": np.round(world_to_camera @ (centre - eye), 6).tolist(),
                           "axes": np.round((world_to_camera @ self.rotation).T, 6).tolist(),
                           "corners_m": np.round((self.corners() - eye) @ world_to_camera.T, 6).tolist()}}


def placed_spec(prop: Prop) -> PropSpec:
    """The spec that puts ``prop`` (world frame) back where it stands, its kind (and colour) kept: for
    a stool or table placed over more frames than are filmed (the benchmark places a clip segment's
    stool over the whole segment, whatever part of it a run renders)."""
    return PropSpec(prop.kind, 1, (prop.x, prop.z, prop.width, prop.depth, prop.height, prop.yaw_deg), prop.spec)


def parse_prop_spec(text: str, where: str = "--prop") -> PropSpec:
    """``stool[:K]``, ``table[:K]`` or ``box:x,z,w,d,h[,yaw]`` -> :class:`PropSpec`; ConfigError names
    the spec and says how to write one."""
    if not isinstance(text, str):
        raise ConfigError(f"{where} {text!r}: a prop is a string; {PROP_HELP}")
    kind, _, rest = text.strip().partition(":")
    kind = kind.lower()
    if kind in ("stool", "table"):
        if rest and not rest.strip().isdigit():
            raise ConfigError(f"{where} {text!r}: after '{kind}:' comes the number of the person it is for "
                              f"(1, 2, ...), got {rest!r}; {PROP_HELP}")
        person = int(rest) if rest else 1
        if person < 1:
            raise ConfigError(f"{where} {text!r}: people are numbered from 1; {PROP_HELP}")
        return PropSpec(kind, person, None, text)
    if kind != "box":
        raise ConfigError(f"{where} {text!r}: unknown prop {kind!r}; {PROP_HELP}")
    if not _BOX.match(rest):
        raise ConfigError(f"{where} {text!r}: a box needs x,z,w,d,h or x,z,w,d,h,yaw (metres, degrees), "
                          f"got {rest!r}; {PROP_HELP}")
    values = [float(v) for v in rest.split(",")]
    x, z, w, d, h = values[:5]
    yaw = values[5] if len(values) == 6 else 0.0
    for name, value in (("x", x), ("z", z)):
        if not (math.isfinite(value) and abs(value) <= MAX_PROP_DISTANCE_M):
            raise ConfigError(f"{where} {text!r}: {name} = {value} m; keep it within ±{MAX_PROP_DISTANCE_M:g} m")
    lo, hi = SIZE_RANGE_M
    for name, value in (("width", w), ("depth", d), ("height", h)):
        if not lo <= value <= hi:
            raise ConfigError(f"{where} {text!r}: {name} = {value} m; give {lo:g}..{hi:g} m")
    if not math.isfinite(yaw):
        raise ConfigError(f"{where} {text!r}: yaw must be a finite number of degrees, got {yaw}")
    return PropSpec("box", 1, (x, z, w, d, h, yaw), text)


def seat_bones(body: SkinnedBody) -> np.ndarray:
    """(B,) bool: the bones the pelvis and the hip joints alone move (pelvis, buttocks, thighs)."""
    hips = {JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]}
    out = np.zeros(len(body.bone_names), bool)
    for b, (joint, parent) in enumerate(zip(body.bone_joint, body.bone_parents)):
        out[b] = int(joint) in hips or (int(joint) < 0 and (parent < 0 or out[parent]))  # parents come first
    return out


def _lowest_hips(body: SkinnedBody, poses: np.ndarray, who: str) -> tuple[int, np.ndarray, np.ndarray]:
    """(frame where the hips are lowest, mid-hip path (N, 3) world m, the seated frames (N,) bool);
    ConfigError when they never go below :data:`SIT_SHARE` of their standing height."""
    hips = body.posed_points(poses, ["mid_hip"])[:, 0]
    standing = float(body.posed_points(body.rest_pose((0.0, body.floor_offset, 0.0))[None], ["mid_hip"])[0, 0, 1])
    low = int(np.argmin(hips[:, 1]))
    if hips[low, 1] > SIT_SHARE * standing:
        raise ConfigError(f"{who} never sits: the hips go no lower than {hips[low, 1]:.2f} m (standing "
                          f"{standing:.2f} m, seated below {SIT_SHARE * standing:.2f} m) in these frames; give a "
                          "clip or frames (--frames, a person's start) where the person sits, or place a box "
                          "yourself with --prop box:x,z,w,d,h[,yaw]")
    return low, hips, hips[:, 1] <= hips[low, 1] + SIT_BAND_M


def stool_for(body: SkinnedBody, poses: np.ndarray, rotations: np.ndarray, skinning: str = "dqs",
              who: str = "person 1", spec: str = "stool") -> Prop:
    """The stool a person sits on: poses (N, 36) and root rotations (N, 3, 3) body -> world of the
    person placed in the world (:func:`swarmpose.sim.scene.place_in_world`); see the module
    docstring. Its top is the lowest seat vertex over the footprint at the frame of the lowest
    hips (skinned with ``skinning``); ConfigError when none lies over it or the seat is not
    0.1..1 m high."""
    low, hips, seated = _lowest_hips(body, poses, who)
    x, z = (float(v) for v in hips[seated][:, [0, 2]].mean(axis=0))
    forward = rotations[low] @ np.array([0.0, 0.0, 1.0])
    yaw = math.degrees(math.atan2(forward[0], forward[2]))
    probe = Prop("stool", x, z, STOOL_SIZE_M, STOOL_SIZE_M, 1.0, yaw, spec)
    vertices = body.skin(body.transforms(poses[low:low + 1]), skinning)[0]
    dominant = body.skin_indices[np.arange(len(vertices)), np.argmax(body.skin_weights, axis=1)]
    local = probe.local(vertices[seat_bones(body)[dominant]])
    over = (np.abs(local[:, 0]) <= 0.5 * STOOL_SIZE_M) & (np.abs(local[:, 2]) <= 0.5 * STOOL_SIZE_M)
    seat = float(local[over, 1].min()) if over.any() else math.nan
    if not 0.1 <= seat <= 1.0:
        raise ConfigError(f"{who}: the seat (the buttocks and thighs over a {STOOL_SIZE_M:g} m stool under the "
                          f"lowest hips) is {seat:.2f} m high, outside 0.1..1 m; place a box yourself with "
                          "--prop box:x,z,w,d,h[,yaw]")
    return Prop("stool", x, z, STOOL_SIZE_M, STOOL_SIZE_M, seat, yaw, spec)


def table_for(body: SkinnedBody, poses: np.ndarray, eye: np.ndarray, who: str = "person 1",
              spec: str = "table") -> Prop:
    """The table between the camera at ``eye`` (3,) world m and a person (poses (N, 36), world
    frame); see the module docstring. ConfigError when the person comes too near the camera to
    leave room for it."""
    hips = body.posed_points(poses, ["mid_hip"])[:, 0]
    seat = hips[int(np.argmin(hips[:, 1]))] * [1.0, 0.0, 1.0]
    ahead = (np.asarray(eye, float) - seat) * [1.0, 0.0, 1.0]
    span = float(np.linalg.norm(ahead))
    ahead /= span
    across = np.cross([0.0, 1.0, 0.0], ahead)
    width, depth, height = TABLE_SIZE_M
    points = body.posed_points(poses).reshape(-1, 3) - seat
    beside = np.abs(points @ across) <= 0.5 * width + TABLE_GAP_M
    near = float(np.max(points[beside] @ ahead, initial=0.0)) + TABLE_GAP_M
    if near + depth > span - TABLE_CAMERA_CLEARANCE_M:
        raise ConfigError(f"{who} comes within {span - near + TABLE_GAP_M:.2f} m of the camera: no room for a "
                          f"{depth:g} m deep table between them; give a larger --camera-distance or place a box "
                          "yourself with --prop box:x,z,w,d,h[,yaw]")
    centre = seat + ahead * (near + 0.5 * depth)
    yaw = math.degrees(math.atan2(ahead[0], ahead[2]))
    return Prop("table", float(centre[0]), float(centre[2]), width, depth, height, yaw, spec)


def place_props(specs: Sequence[PropSpec], bodies: Sequence[SkinnedBody], poses: Sequence[np.ndarray],
                rotations: Sequence[np.ndarray], eye: np.ndarray, skinning: str = "dqs") -> tuple[Prop, ...]:
    """Each spec as a :class:`Prop` in the world frame, for people placed in the world (per person
    its body, poses (N, 36) and root rotations (N, 3, 3)) filmed from ``eye`` (3,) world m;
    ConfigError names a spec that asks for a person the scene does not have."""
    props = []
    for spec in specs:
        if spec.box is not None:  # a box, or a stool or table placed before (placed_spec)
            x, z, w, d, h, yaw = spec.box
            props.append(Prop(spec.kind, x, z, w, d, h, yaw, spec.text))
            continue
        if spec.person > len(bodies):
            raise ConfigError(f"--prop {spec.text!r} is for person {spec.person}, but the scene has "
                              f"{len(bodies)}; {PROP_HELP}")
        k = spec.person - 1
        who = f"person {spec.person}"
        if spec.kind == "stool":
            props.append(stool_for(bodies[k], poses[k], rotations[k], skinning, who, spec.text))
        else:
            props.append(table_for(bodies[k], poses[k], eye, who, spec.text))
    for prop in props:
        x, y, z = prop.local(eye)
        if abs(x) <= 0.5 * prop.width and 0.0 <= y <= prop.height and abs(z) <= 0.5 * prop.depth:
            raise ConfigError(f"--prop {prop.spec!r}: the camera stands inside it; move the box or the camera")
    return tuple(props)
