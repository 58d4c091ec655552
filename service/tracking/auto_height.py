"""Automatic height: a body whose shape the user did not give is scaled to the person's stature.

The default bodies are 1.75 m tall; people are not. On UTD-MHAD's real Kinect depth the default
built-in body tracks the 1.50-1.63 m subjects 15-25 mm worse than the same body at their height
(BENCHMARKS.md, issue 12). Personalisation (``--personalize N``) fits the whole shape but costs
tens of seconds; this is its cheap first step, on by default (``auto_height``).

**The measure** (:func:`person_stature`). At a tracked frame where the person stands upright on
at least one leg, by the fitted pose (:func:`upright`) and by the lifted joints J^e
(:func:`lifted_upright`), the stature is the height of the top of the head above the floor,
along the floor's normal, where a floor is seen under the person (:func:`floor_plane`), else
above the lowest points of the feet, along the fitted torso's up axis; divided by
:data:`UPRIGHT_SHARE` (and less :data:`HIDDEN_SOLE_SHARE` without a floor). The top of the head
and the feet are the person's points near the lines along the axis through the model's head and
ankles, so a raised hand is not the head. The fitted model only says where to look: its size
does not enter the measure.

*Design change:* the first version compared the person's extent with the fitted model's own
render, measured the same way, so that the percentiles and the posture would cancel. They do
for the true pose (within 0.5 %), but the tracker's fits absorb a wrong size (a body too tall
sinks its feet below the floor the depth cannot see there, bends, leans): the 1.75 m body fitted
to a 1.75 m subject measured 1.68 m, a 1.55 m subject's wave 1.70 m. The head above the floor is
the observation's alone (four built-in subjects of 1.55-1.95 m: within 1.1 cm).

**The person's points** (:func:`person_mask`): the observed pixels inside the model's silhouette
grown by :data:`GROW_DOWN_UP` of its pixel height up and down and :data:`GROW_SIDEWAYS` sideways
(a taller person reaches beyond the model's head), within :data:`DEPTH_BAND_M` of the model's
median depth: a wall farther behind the person than that is left out.

**The body** (:class:`HeightFittingTracker`): the median of the first :data:`FIRST_ESTIMATES`
upright frames' statures scales the body uniformly about its origin (:func:`scaled_body`; for
the built-in body exactly its stature parameter, for a MakeHuman body its size at unchanged
proportions); the median of the first :data:`ESTIMATES` scales it once more, and it is then
locked. The factor is clamped to :data:`FACTOR_LIMITS`. A person who never stands upright keeps
the given body; a new person starts from the given body again.

Limits: a person jumping (jumping jacks) is measured in the air as well (a 1.55 m subject:
1.61 m); MakeHuman subjects came out 1.6-1.7 % short (their heads' top against the stature
differ from the built-in body's, on which :data:`UPRIGHT_SHARE` is calibrated).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import cv2
import numpy as np

from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.gpu.reference import raycast_tiles
from swarmpose.gpu.tile import TileBox
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker, observed_depth
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult

log = logging.getLogger(__name__)

UPRIGHT_MAX_RAD = 0.45
"""An upright pose: a leg whose knee is bent, and whose thigh is away from the line down the
torso, by at most this (rad, about 26 degrees) ..."""
LIFTED_MAX_RAD = 0.6
"""... and the lifted joints agree: a thigh and a shin within this (rad, about 34 degrees) of the
line down (they are noisier than the fitted pose)."""
FIRST_ESTIMATES = 3
"""Upright frames after which the body is scaled a first time (median of their factors) ..."""
ESTIMATES = 10
"""... and after which it is scaled by the median of all and kept: UTD-MHAD's clips are two
seconds long, so the body should change early, and real depth moves one frame's measure by a
few centimetres (the median of ten is steadier)."""
PERCENTILES = (0.5, 99.5)
"""The lowest and highest of a set of points along the axis (percent of them), against stray pixels."""
GROW_DOWN_UP = 0.15
"""The model's silhouette is grown by this share of its pixel height up and down."""
GROW_SIDEWAYS = 0.05
"""... and by this share of its pixel height to the sides."""
DEPTH_BAND_M = 0.35
"""The person's points lie within this of the model's median depth (m)."""
MIN_PIXELS = 300
"""Fewest pixels of the model and of the person a measure needs."""
FLAT_MAX_RAD = 0.5
"""Surfaces whose normal is within this (rad) of the up axis are flat: a floor's candidates."""
END_RADIUS_M = {"head": 0.15, "left_ankle": 0.25, "right_ankle": 0.25}
"""The top of the head, and the soles where no floor is seen, are looked for within this distance
(m) of the lines along the axis through the model's head and ankles (the toes lie up to 20 cm
in front of an ankle) ..."""
END_PIXELS = 20
"""... among at least this many pixels."""
UPRIGHT_SHARE = 0.985
"""The height of the top of the head above the soles of an upright person (the 99.5th percentile
of the head's points), as a share of their stature. Calibrated on four built-in subjects
tracked by the 1.75 m body (1.55-1.95 m; walk, wave, squat; simulated Kinect noise), whose
statures came out 0.7-2.1 % short with a share of 1."""
HIDDEN_SOLE_SHARE = 0.015
"""Without a floor, how much of the stature lies below the lowest points seen of the feet: a camera
above them sees their tops and fronts, not the soles' edge (ray-cast subjects of 1.50-1.95 m
standing: 1.5-1.8 % less than with a floor under them)."""
FLOOR_SHARE = 0.2
"""A floor is looked for in the lowest share of the person's extent ..."""
FLOOR_PIXELS = 100
"""... and seen when at least this many flat pixels outside the model's render lie there ..."""
FLOOR_MAX_TILT_RAD = 0.35
"""... and the plane through them is within this (rad, 20 degrees) of lying across the fitted torso
(on UTD-MHAD's background-free depth, 30-40 flat pixels around the shoes made planes at any angle)."""
FACTOR_LIMITS = (0.8, 1.2)
"""The scale factor is clamped to this range (1.40-2.10 m from a 1.75 m body)."""


def applies(body_spec: str, shape: str, config: TrackerConfig) -> bool:
    """Whether a tracker of ``body_spec`` (``--body``) with ``shape`` (``--shape``) under ``config``
    measures the height: ``auto_height`` is on, the body is ``builtin`` or ``makehuman:DIR`` with no
    shape given (a .glb is someone's own body), nothing personalises it and the mode fits a body."""
    spec = body_spec.strip().lower()
    own = spec == "builtin" or spec.startswith("makehuman:")
    return bool(config.auto_height and own and not shape.strip() and config.personalize == 0
                and config.mode != "lift")


def scaled_body(body: SkinnedBody, factor: float) -> SkinnedBody:
    """``body`` scaled uniformly by ``factor`` about its origin (the pose's root): the rest
    vertices, bone pivots, named points and the bind matrices' translations. Skinning and
    triangles are unchanged, so a tracker takes it with :meth:`BodyTracker.set_body`."""
    binds = np.array(body.bind_matrices, dtype=np.float64, copy=True)
    binds[:, :3, 3] *= factor
    return replace(body, name=f"{body.name} x{factor:.3f}", vertices=np.asarray(body.vertices) * factor,
                   bone_heads=np.asarray(body.bone_heads) * factor,
                   bind_matrices=binds.astype(np.asarray(body.bind_matrices).dtype),
                   point_rest=np.asarray(body.point_rest) * factor,
                   metadata={**body.metadata, "scaled_to_height": float(factor)})


_LEGS = ("mid_hip", "neck", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between vectors ``a`` and ``b`` (3,)."""
    cos = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-9)
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def upright(body: SkinnedBody, pose: np.ndarray, max_rad: float = UPRIGHT_MAX_RAD) -> bool:
    """Whether ``body`` at ``pose`` (36,) stands upright on at least one leg: a knee bent by at
    most ``max_rad`` whose thigh is within ``max_rad`` of the line from the neck down to the mid
    hip (a walk's swing leg bends far more, the stance leg does not)."""
    p = dict(zip(_LEGS, body.posed_points(np.asarray(pose, float)[None], _LEGS)[0]))
    down = p["mid_hip"] - p["neck"]
    for side in ("left", "right"):
        thigh = p[f"{side}_knee"] - p[f"{side}_hip"]
        shin = p[f"{side}_ankle"] - p[f"{side}_knee"]
        if _angle(thigh, shin) <= max_rad and _angle(thigh, down) <= max_rad:
            return True
    return False


def lifted_upright(names: tuple[str, ...], xyz: np.ndarray, up: np.ndarray, max_rad: float = LIFTED_MAX_RAD) -> bool:
    """Whether the lifted joints J^e (``names``, ``xyz`` (n, 3) m, NaN rows: no depth) stand upright
    on at least one leg: its thigh (hip to knee) and shin (knee to ankle) both within ``max_rad``
    of ``-up`` (3,). The detection's own view, beside the fitted pose's: a seated person seen from
    the front, whose thighs point at the camera, can be fitted with straight legs."""
    at = {n: p for n, p in zip(names, np.asarray(xyz, float)) if np.all(np.isfinite(p))}
    for side in ("left", "right"):
        hip, knee, ankle = (at.get(f"{side}_{j}") for j in ("hip", "knee", "ankle"))
        if hip is None or knee is None or ankle is None:
            continue
        if _angle(knee - hip, -up) <= max_rad and _angle(ankle - knee, -up) <= max_rad:
            return True
    return False


def person_mask(observed: np.ndarray, model: np.ndarray) -> np.ndarray:
    """(H, W) bool: the observed pixels of the person around the model's render (see the module
    docstring). observed, model: (H, W) depth m, NaN or 0 where none."""
    hit = model > 0
    rows = np.flatnonzero(hit.any(axis=1))
    tall = int(rows[-1] - rows[0] + 1)
    kernel = np.ones((2 * int(GROW_DOWN_UP * tall) + 1, 2 * int(GROW_SIDEWAYS * tall) + 1), np.uint8)
    around = cv2.dilate(hit.astype(np.uint8), kernel).astype(bool)
    near = float(np.median(model[hit]))
    with np.errstate(invalid="ignore"):
        return around & np.isfinite(observed) & (observed > 0) & (np.abs(observed - near) < DEPTH_BAND_M)


def _points(depth: np.ndarray, intrinsics: Intrinsics, corner: tuple[int, int] = (0, 0)) -> np.ndarray:
    """(h, w, 3) m: every pixel of ``depth`` (h, w) m back-projected (OpenCV camera axes), the
    window's top-left pixel being the image's ``corner`` (column, row)."""
    rows, cols = np.indices(depth.shape, dtype=np.float64)
    rows, cols = rows + corner[1], cols + corner[0]
    z = depth.astype(np.float64)
    return np.stack([(cols - intrinsics.cx) * z / intrinsics.fx, (rows - intrinsics.cy) * z / intrinsics.fy, z], -1)


def _window(verts: np.ndarray, intrinsics: Intrinsics) -> TileBox | None:
    """The image window (whole pixels) that holds the projection of ``verts`` (V, 3) m and the
    growth of :func:`person_mask` around it, plus a pixel for the normals' neighbours; None when
    the body is behind the camera or outside the image."""
    if np.any(verts[:, 2] <= 1e-3):
        return None
    uv = intrinsics.project(verts)
    (u_lo, v_lo), (u_hi, v_hi) = np.floor(uv.min(axis=0)), np.ceil(uv.max(axis=0))
    tall = v_hi - v_lo + 1
    grow_u, grow_v = int(GROW_SIDEWAYS * tall) + 2, int(GROW_DOWN_UP * tall) + 2
    u0, v0 = int(max(u_lo - grow_u, 0)), int(max(v_lo - grow_v, 0))
    u1, v1 = int(min(u_hi + grow_u + 1, intrinsics.width)), int(min(v_hi + grow_v + 1, intrinsics.height))
    if u1 <= u0 or v1 <= v0:
        return None
    return TileBox(u0, v0, u1 - u0, v1 - v0, u1 - u0, v1 - v0)


def facing_along(points: np.ndarray, axis: np.ndarray, max_rad: float = FLAT_MAX_RAD) -> np.ndarray:
    """(H, W) bool: the pixels of ``points`` (H, W, 3) m whose surface normal (from the central
    differences of their neighbours) lies within ``max_rad`` of unit ``axis`` (3,), either way:
    surfaces across the axis, such as the floor under an upright person."""
    across = np.zeros_like(points)
    down = np.zeros_like(points)
    across[:, 1:-1] = points[:, 2:] - points[:, :-2]
    down[1:-1] = points[2:] - points[:-2]
    normal = np.cross(across, down)
    length = np.linalg.norm(normal, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(normal @ axis) / length
    return np.nan_to_num(cos) > np.cos(max_rad)


def floor_plane(points: np.ndarray, up: np.ndarray, mask: np.ndarray, hit: np.ndarray,
                flat: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The floor under the person, None when none is seen: (unit normal (3,) on the side of ``up``,
    level: the normal's dot product with the floor's points, m). Its points are the flat pixels
    (``flat``) of ``mask`` outside the model's render ``hit`` in the lowest :data:`FLOOR_SHARE` of
    the person's extent along ``up``, at least :data:`FLOOR_PIXELS` of them; the plane through
    them is their least-squares fit (SVD), and a floor only when it is within
    :data:`FLOOR_MAX_TILT_RAD` of lying across ``up``."""
    along = np.nan_to_num(points @ up)
    low, high = np.percentile(along[mask], PERCENTILES)
    floor = mask & flat & ~hit & (along < low + FLOOR_SHARE * (high - low))
    if floor.sum() < FLOOR_PIXELS:
        return None
    on = points[floor]
    centre = np.median(on, axis=0)
    normal = np.linalg.svd(on - centre, full_matrices=False)[2][2]
    normal = normal if normal @ up > 0 else -normal
    if _angle(normal, up) > FLOOR_MAX_TILT_RAD:  # a few flat pixels that are no floor (shoes, noise)
        return None
    return normal, float(centre @ normal)


_ENDS = ("head", "left_ankle", "right_ankle")


def _near_axis(points: np.ndarray, along: np.ndarray, point: np.ndarray, axis: np.ndarray,
               radius: float) -> np.ndarray:
    """(N,) bool: which ``points`` (N, 3) m (``along``: their dot products with unit ``axis``) lie
    within ``radius`` (m) of the line through ``point`` (3,) along ``axis``."""
    across = points - point - np.outer(along - point @ axis, axis)
    return np.linalg.norm(across, axis=1) < radius


def person_stature(body: SkinnedBody, pose: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics) -> float | None:
    """The stature (m) of the person in ``depth`` (H, W) m whom ``body`` was fitted to at ``pose``
    (36,), None when the model or the person covers fewer than :data:`MIN_PIXELS` pixels (or
    its head or feet fewer than :data:`END_PIXELS`): the height of the top of the head above the
    floor where a floor is seen (along its normal), over :data:`UPRIGHT_SHARE`; else above the
    lowest points of the feet (along the fitted torso's up axis), over :data:`UPRIGHT_SHARE` less
    :data:`HIDDEN_SOLE_SHARE`. The top of the head and the feet are the highest and lowest
    (:data:`PERCENTILES`) of the person's points within :data:`END_RADIUS_M` of the lines along
    the axis through the model's head and ankles (a raised hand is not the head)."""
    pose = np.asarray(pose, float)
    verts = body.pose(pose[None], "dqs")[0]
    window = _window(verts, intrinsics)
    if window is None:
        return None
    model = raycast_tiles(verts[None], np.asarray(body.triangles), window.rays(intrinsics))[0]
    hit = model > 0
    if hit.sum() < MIN_PIXELS:
        return None
    u0, v0 = int(window.u0), int(window.v0)
    depth = np.asarray(depth, np.float32)[v0:v0 + window.th, u0:u0 + window.tw]
    mask = person_mask(depth, model)
    if mask.sum() < MIN_PIXELS:
        return None
    up = quaternion_to_matrix(pose[3:7])[:, 1]
    seen = _points(depth, intrinsics, (u0, v0))
    floor = floor_plane(seen, up, mask, hit, facing_along(seen, up))
    axis = up if floor is None else floor[0]
    person = seen[mask]
    along = person @ axis
    near = {name: _near_axis(person, along, point, axis, END_RADIUS_M[name]) for name, point in
            zip(_ENDS, body.posed_points(pose[None], _ENDS)[0])}
    feet = near["left_ankle"] | near["right_ankle"]
    if near["head"].sum() < END_PIXELS or (floor is None and feet.sum() < END_PIXELS):
        return None
    top = float(np.percentile(along[near["head"]], PERCENTILES[1]))
    if floor is not None:
        return (top - floor[1]) / UPRIGHT_SHARE
    return (top - float(np.percentile(along[feet], PERCENTILES[0]))) / (UPRIGHT_SHARE - HIDDEN_SOLE_SHARE)


class HeightFittingTracker(BodyTracker):
    """A :class:`BodyTracker` that scales its body to the person's height on the first upright
    frames it tracks: at once after :data:`FIRST_ESTIMATES` of them, finally after
    :data:`ESTIMATES`, then keeps it (see the module docstring).

    :meth:`height_state` reports ``state`` (``measuring`` or ``locked``), the ``factors``
    measured so far (each frame's stature over the given body's), the
    ``factor`` applied now (1 at first) and the body's ``height_m``."""

    def __init__(self, body: SkinnedBody, intrinsics: Intrinsics, config: TrackerConfig | None = None,
                 context: ClContext | None = None, body_id: int = 0):
        super().__init__(body, intrinsics, config, context, body_id)
        self.given_body = body
        self.factors: list[float] = []
        self.factor = 1.0
        self.locked = False

    def new_person(self) -> None:
        """Another person: the given body again, and a new measure."""
        super().new_person()
        if self.factor != 1.0:
            self.set_body(self.given_body)
        self.factors, self.factor, self.locked = [], 1.0, False

    def step(self, frame: Frame, joints: Joints2D | None, others_removed: bool = False) -> BodyResult:
        result = super().step(frame, joints, others_removed)
        found = result.found
        if not self.locked and found.state != "lost" and found.pose is not None and self._upright(found.pose):
            stature = person_stature(self.body, found.pose, observed_depth(frame.depth), self.intrinsics)
            if stature is not None and np.isfinite(stature):
                self.factors.append(stature / self.given_body.height)
                if len(self.factors) in (FIRST_ESTIMATES, ESTIMATES):
                    self._rescale()
        return result

    def _upright(self, pose: np.ndarray) -> bool:
        """Whether the fitted ``pose`` (36,) and the frame's lifted joints both stand upright."""
        if not upright(self.body, pose) or self.objective is None:
            return False
        targets = self.objective.targets
        return lifted_upright(targets.names, targets.xyz, quaternion_to_matrix(np.asarray(pose, float)[3:7])[:, 1])

    def _rescale(self) -> None:
        """Scale the given body by the median factor so far (clamped); lock it after :data:`ESTIMATES`."""
        self.factor = float(np.clip(np.median(self.factors), *FACTOR_LIMITS))
        self.set_body(scaled_body(self.given_body, self.factor))
        self.locked = len(self.factors) >= ESTIMATES
        log.log(logging.INFO if self.locked else logging.DEBUG,
                "body %d: height %.3f m from the depth of %d upright frames (the body scaled by %.3f)%s",
                self.body_id, self.body.height, len(self.factors), self.factor,
                "" if self.locked else "; measuring on")

    def personalisation(self) -> dict:
        """This body's state as the status and info messages' ``personalisation`` reports it:
        ``collecting`` its :data:`ESTIMATES` upright frames (``frames`` so far), then ``locked``;
        ``parameters``: the ``scale`` applied to the given body; ``height_m``: the body's now."""
        return {"id": self.body_id, "state": "locked" if self.locked else "collecting",
                "frames": min(len(self.factors), ESTIMATES), "needed": ESTIMATES,
                "parameters": {"scale": round(self.factor, 4)}, "height_m": round(self.body.height, 4)}

    def height_state(self) -> dict:
        """The state of the measure (see the class docstring)."""
        return {"id": self.body_id, "state": "locked" if self.locked else "measuring",
                "factors": [round(f, 4) for f in self.factors], "factor": round(self.factor, 4),
                "height_m": round(self.body.height, 4)}
