"""A standing person's stature measured on the depth, where a fitted body says where to look.

Used by the automatic height (:mod:`swarmpose.personalise.auto_height`; the method, and why the
fitted model's own size stays out of it, are in its docstring). :func:`person_stature` measures
one frame; :func:`upright` and :func:`lifted_upright` say whether a frame may be measured.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.floor import grid_normals, plane_fit, ransac_plane_inliers
from swarmpose.gpu.reference import raycast_tiles
from swarmpose.gpu.tile import TileBox

UPRIGHT_MAX_RAD = 0.45
"""An upright pose: a leg whose knee is bent, and whose thigh is away from the line down the
torso, by at most this (rad, about 26 degrees) ..."""
LIFTED_MAX_RAD = 0.6
"""... and the lifted joints agree: a thigh and a shin within this (rad, about 34 degrees) of the
line down (they are noisier than the fitted pose)."""
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
HAND_RADIUS_M = 0.10
"""Points this close (m) to a fitted forearm and hand are not the head: a hand raised over it ..."""
HAND_LENGTH_M = 0.18
"""... the hand reaching this far (m) beyond the wrist ..."""
HAND_ON_HEAD_M = 0.20
"""... and no measure at all while a fitted wrist is this close (m) to the head's centre (a hand on
the head)."""
EDGE_JUMP_M = 0.05
"""Two neighbours of a pixel (two pixels apart) whose depths differ by more than this (m) ..."""
EDGE_JUMP_SHARE = 0.08
"""... and this share of its depth lie on two surfaces (a floor seen at a grazing angle steps by
z / (f h) of its depth a row: 1.4 % at 3.2 m, 0.9 m under a 262-pixel focal length)."""
FLAT_MAX_RAD = 0.5
"""Surfaces whose normal is within this (rad) of the up axis are flat: a floor's candidates."""
END_RADIUS_M = {"head": 0.15, "left_ankle": 0.25, "right_ankle": 0.25}
"""The top of the head, and the soles where no floor is seen, are looked for within this distance
(m) of the lines along the axis through the model's head and ankles (the toes lie up to 20 cm
in front of an ankle) ..."""
END_PIXELS = 20
"""... among at least this many pixels (the head's above the fitted neck, the feet's below the
fitted knees)."""
UPRIGHT_SHARE = 0.994
"""The height of the top of the head above the soles of an upright person (the 99.5th percentile
of the head's points), as a share of their stature. Calibrated on four built-in subjects
tracked by the 1.75 m body (1.55-1.95 m; walk, wave, squat; simulated Kinect noise, a floor in
view), whose statures came out 0.6 % short to 0.3 % tall with a share of 1 (0.994: their mean)."""
HIDDEN_SOLE_SHARE = 0.008
"""Without a floor, how much of the stature lies below the lowest points seen of the feet: a camera
above them sees their tops and fronts, not the soles' edge (ray-cast subjects of 1.50-1.95 m
standing alone measured 0.6-0.9 % shorter than on a floor)."""
LONG_AXIS_MAX_RAD = 0.8
"""Without a floor the stature is measured along the fitted body's long axis (:func:`long_axis`),
not the fitted pelvis's up axis: the pelvis leans with the fit (UTD-MHAD, subject 2: 1-22 degrees
from the camera's vertical by sequence, while the person's own axis stays within 4-7 degrees of
it), and the measure shortens by the cosine (a15_s2: 1.44 m against 1.51 m for the person's
extent). The pelvis's axis is kept where the two differ by more than this (rad, 46 degrees)."""
FLOOR_SHARE = 0.2
"""A floor is looked for in the lowest share of the person's extent ..."""
FLOOR_PIXELS = 100
"""... and seen when at least this many flat pixels outside the model's render lie there ..."""
FLAT_PIXELS = FLOOR_PIXELS
"""... or, where fewer of them are flat, among all the pixels outside the render there: at range
the depth noise turns a floor's normals every way (simulated Kinect noise at 640 x 480, from
about 4 m; at 5-5.5 m 3-9 flat pixels of 250-510; without a floor the soles were taken among noisy
floor points, +1.5 to +2.7 %) ..."""
FALLBACK_MAX_TILT_RAD = 0.15
"""... and then a floor only within this (rad, about 9 degrees) of lying across the fitted body's
long axis (:func:`long_axis`; the fitted pelvis's leans too much: at 5 m it missed a true floor):
without the flat test, a fit whose feet miss the person's leaves their shoes and shins outside the
render, and a plane through them tilts by 15-19 degrees (ray-cast subjects alone; a true floor at
3.2-5.5 m with noise: 0-1 degree)."""
FLOOR_INLIER_M = 0.02
"""... within this (m) of the RANSAC plane through them ..."""
FLOOR_RANSAC_ITERATIONS = 100
"""(RANSAC's hypotheses)"""
FLOOR_BELOW_FEET_M = (0.05, 0.10)
"""... and the feet's lowest points are at most the first (m) below it and the second above it
(a step or a table is no floor under the feet) ..."""
FLOOR_MAX_TILT_RAD = 0.35
"""... and the plane through them is within this (rad, 20 degrees) of lying across the fitted torso
(on UTD-MHAD's background-free depth, 30-40 flat pixels around the shoes made planes at any angle)."""


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


def lifted_upright(names: tuple[str, ...], xyz: np.ndarray, up: np.ndarray, max_rad: float = LIFTED_MAX_RAD,
                   max_bend_rad: float = np.pi) -> bool:
    """Whether the lifted joints J^e (``names``, ``xyz`` (n, 3) m, NaN rows: no depth) stand upright
    on at least one leg: its thigh (hip to knee) and shin (knee to ankle) both within ``max_rad``
    of ``-up`` (3,), and its knee bent by at most ``max_bend_rad``. The detection's own view,
    beside the fitted pose's: a seated person seen from the front, whose thighs point at the
    camera, can be fitted with straight legs."""
    at = {n: p for n, p in zip(names, np.asarray(xyz, float)) if np.all(np.isfinite(p))}
    for side in ("left", "right"):
        hip, knee, ankle = (at.get(f"{side}_{j}") for j in ("hip", "knee", "ankle"))
        if hip is None or knee is None or ankle is None:
            continue
        thigh, shin = knee - hip, ankle - knee
        if _angle(thigh, -up) <= max_rad and _angle(shin, -up) <= max_rad and _angle(thigh, shin) <= max_bend_rad:
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
    """(H, W) bool: the pixels of ``points`` (H, W, 3) m (NaN: no depth) whose surface normal
    (:func:`~swarmpose.detect.floor.grid_normals`: central differences, none on the border or next
    to a missing point) lies within ``max_rad`` of unit ``axis`` (3,), either way: surfaces across
    the axis, such as the floor under an upright person. A pixel whose neighbours' depths differ by
    more than :data:`EDGE_JUMP_M` and :data:`EDGE_JUMP_SHARE` of its depth is on an edge and has
    no normal either."""
    z = points[..., 2]
    jump = np.maximum(EDGE_JUMP_M, EDGE_JUMP_SHARE * z[1:-1, 1:-1])  # a neighbour beyond it is another surface
    smooth = np.zeros(z.shape, bool)
    with np.errstate(invalid="ignore"):
        smooth[1:-1, 1:-1] = ((np.abs(z[1:-1, 2:] - z[1:-1, :-2]) < jump) & (np.abs(z[2:, 1:-1] - z[:-2, 1:-1]) < jump))
        return smooth & (np.abs(grid_normals(points) @ axis) > np.cos(max_rad))


def floor_plane(points: np.ndarray, up: np.ndarray, mask: np.ndarray, hit: np.ndarray,
                flat: np.ndarray, standing: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The floor under the person, None when none is seen: (unit normal (3,) on the side of ``up``,
    level: the normal's dot product with the floor's points, m). Its points are the flat pixels
    (``flat``) of ``mask`` outside the model's render ``hit`` in the lowest :data:`FLOOR_SHARE` of
    the person's extent along ``up`` (all those pixels where fewer than :data:`FLAT_PIXELS` are
    flat: noisy depth at range, the plane then held to :data:`FALLBACK_MAX_TILT_RAD` of the fitted
    body's ``standing`` axis (3,), :func:`long_axis`); the plane is the RANSAC plane among them
    (:func:`ransac_plane_inliers`: the tops of shoes beside the model are flat too) refitted by
    least squares (SVD) to its inliers, at least :data:`FLOOR_PIXELS` of them, and a floor only
    when it is within :data:`FLOOR_MAX_TILT_RAD` of lying across ``up``."""
    along = np.nan_to_num(points @ up)
    low, high = np.percentile(along[mask], PERCENTILES)
    low_around = mask & ~hit & (along < low + FLOOR_SHARE * (high - low))
    floor = low_around & flat
    max_tilt, across = FLOOR_MAX_TILT_RAD, up
    if floor.sum() < FLAT_PIXELS:
        floor, max_tilt, across = low_around, FALLBACK_MAX_TILT_RAD, standing
    if floor.sum() < FLOOR_PIXELS:
        return None
    on = ransac_plane_inliers(points[floor], FLOOR_INLIER_M, FLOOR_RANSAC_ITERATIONS)
    if len(on) < FLOOR_PIXELS:
        return None
    normal, offset = plane_fit(on)
    if normal @ up <= 0:
        normal, offset = -normal, -offset
    if _angle(normal, across) > max_tilt:  # a few flat pixels that are no floor (shoes, noise)
        return None
    return normal, -offset


_MARKS = ("head", "neck", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_knee", "right_knee",
          "left_ankle", "right_ankle")


def _near_axis(points: np.ndarray, along: np.ndarray, point: np.ndarray, axis: np.ndarray,
               radius: float) -> np.ndarray:
    """(N,) bool: which ``points`` (N, 3) m (``along``: their dot products with unit ``axis``) lie
    within ``radius`` (m) of the line through ``point`` (3,) along ``axis``."""
    across = points - point - np.outer(along - point @ axis, axis)
    return np.linalg.norm(across, axis=1) < radius


def _near_forearms(points: np.ndarray, marks: dict[str, np.ndarray]) -> np.ndarray:
    """(N,) bool: which ``points`` (N, 3) m lie within :data:`HAND_RADIUS_M` of a fitted forearm
    (the segment from elbow to wrist, prolonged by the hand's length) in ``marks``."""
    near = np.zeros(len(points), bool)
    for side in ("left", "right"):
        elbow, wrist = marks[f"{side}_elbow"], marks[f"{side}_wrist"]
        forearm = wrist - elbow
        length = float(np.linalg.norm(forearm))
        if length < 1e-6:
            continue
        tip = wrist + forearm * (HAND_LENGTH_M / length)
        t = np.clip((points - elbow) @ (tip - elbow) / float((tip - elbow) @ (tip - elbow)), 0.0, 1.0)
        near |= np.linalg.norm(points - (elbow + t[:, None] * (tip - elbow)), axis=1) < HAND_RADIUS_M
    return near


def long_axis(marks: dict[str, np.ndarray], up: np.ndarray, max_rad: float = LONG_AXIS_MAX_RAD) -> np.ndarray:
    """The unit axis (3,) from the middle of the fitted ankles to the fitted neck (``marks``: body
    points by name, m), along which a stature is measured where no floor is seen; ``up`` (3,), the
    fitted pelvis's up axis, where the two lie more than ``max_rad`` apart."""
    axis = marks["neck"] - 0.5 * (marks["left_ankle"] + marks["right_ankle"])
    norm = float(np.linalg.norm(axis))
    if norm < 1e-9 or _angle(axis, up) > max_rad:
        return up
    return axis / norm


def person_stature(body: SkinnedBody, pose: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics) -> float | None:
    """The stature (m) of the person in ``depth`` (H, W) m whom ``body`` was fitted to at ``pose``
    (36,): the height of the top of the head above the floor where a floor is seen under the feet
    (along its normal), over :data:`UPRIGHT_SHARE`; else above the lowest points of the feet
    (along the fitted body's :func:`long_axis`), over :data:`UPRIGHT_SHARE` less :data:`HIDDEN_SOLE_SHARE`.
    The head is the person's points above the fitted neck within :data:`END_RADIUS_M` of the line
    along the axis through the fitted head, the feet those below the fitted knees near the lines
    through the ankles; the top and the lowest points are their :data:`PERCENTILES`.

    The points near the fitted forearms and hands (:func:`_near_forearms`) are left out of the
    head: a hand raised over it would pass for its top. None (no measure) when the model or the
    person covers fewer than :data:`MIN_PIXELS` pixels, the head or the feet fewer than
    :data:`END_PIXELS`, a fitted wrist is within :data:`HAND_ON_HEAD_M` of the head, or the head
    or the feet touch the image's border (cut off, they would be measured short)."""
    pose = np.asarray(pose, float)
    verts = body.pose(pose[None], "dqs")[0]
    window = _window(verts, intrinsics)
    if window is None:
        return None
    up = quaternion_to_matrix(pose[3:7])[:, 1]
    marks = dict(zip(_MARKS, body.posed_points(pose[None], _MARKS)[0]))
    if min(np.linalg.norm(marks[f"{side}_wrist"] - marks["head"]) for side in ("left", "right")) < HAND_ON_HEAD_M:
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
    seen = replace(intrinsics, width=window.tw, height=window.th, cx=intrinsics.cx - u0,
                   cy=intrinsics.cy - v0).point_map(depth)  # the window as a camera of its own
    standing = long_axis(marks, up)  # the axis wherever no floor stands under the feet
    floor = floor_plane(seen, up, mask, hit, facing_along(seen, up), standing)
    axis = standing if floor is None else floor[0]
    rows = np.nonzero(mask)[0] + v0
    person = seen[mask]
    along = person @ axis
    head = (_near_axis(person, along, marks["head"], axis, END_RADIUS_M["head"])
            & (along > marks["neck"] @ axis) & ~_near_forearms(person, marks))
    knees = min(marks["left_knee"] @ axis, marks["right_knee"] @ axis)
    feet = ((_near_axis(person, along, marks["left_ankle"], axis, END_RADIUS_M["left_ankle"])
             | _near_axis(person, along, marks["right_ankle"], axis, END_RADIUS_M["right_ankle"]))
            & (along < knees))
    if head.sum() < END_PIXELS or feet.sum() < END_PIXELS:
        return None
    if rows[head].min() == 0 or rows[feet].max() == intrinsics.height - 1:
        return None

    def ends(along: np.ndarray) -> tuple[float, float]:  # the head's top and the soles along an axis, m
        return float(np.percentile(along[head], PERCENTILES[1])), float(np.percentile(along[feet], PERCENTILES[0]))

    top, soles = ends(along)
    if floor is not None and -FLOOR_BELOW_FEET_M[0] <= soles - floor[1] <= FLOOR_BELOW_FEET_M[1]:
        return (top - floor[1]) / UPRIGHT_SHARE
    if floor is not None:  # a plane, but not the one the feet stand on (a step, a table)
        top, soles = ends(person @ standing)
    return (top - soles) / (UPRIGHT_SHARE - HIDDEN_SOLE_SHARE)


def upright_stature(body: SkinnedBody, pose: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics,
                    names: tuple[str, ...], lifted: np.ndarray, by_fit: bool = True) -> float | None:
    """:func:`person_stature` at a frame where ``body`` at ``pose`` (36,) stands upright
    (:func:`upright`) and so do the frame's lifted joints (``names``, ``lifted`` (n, 3) m:
    :func:`lifted_upright` along the pose's up axis); None at any other frame, or no measure.

    ``by_fit`` False: the fitted pose is not asked; the lifted knee must be as straight as
    :func:`upright` asks of the fitted one instead. For poses tracked with a body of another
    size, which bend to absorb it: a start body 7 cm too tall stood upright at 2 of a female
    walk's 30 frames, her lifted joints at 11 (the same median stature within 1 mm)."""
    pose = np.asarray(pose, float)
    if by_fit and not upright(body, pose):
        return None
    bend = np.pi if by_fit else UPRIGHT_MAX_RAD
    if not lifted_upright(names, lifted, quaternion_to_matrix(pose[3:7])[:, 1], max_bend_rad=bend):
        return None
    return person_stature(body, pose, depth, intrinsics)
