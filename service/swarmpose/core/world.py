"""The floor-aligned world frame: a camera-to-world transform made from a floor plane, applied
to points and poses, and read from an extrinsics file.

World frame (metres, right-handed):

* **y** up: the floor's normal; the floor is ``y = 0``;
* **x** the camera's x axis (the image's right) projected onto the floor;
* **z** = x × y: horizontal, pointing from the scene back towards the camera;
* **origin** on the floor where the caller puts it (the pipeline: under the first tracked
  person's root at the first frame both the floor and that person are known).

For a level camera this is the camera frame turned 180 degrees about x (x right, y up, z
towards the camera), the axes of the BVH files. Transforms are (4, 4) homogeneous matrices
acting on column vectors: ``p_world = R @ p_camera + t`` with ``R = T[:3, :3]``, ``t = T[:3, 3]``.

A floor plane is given in the camera frame (OpenCV axes: x right, y down, z forward) as a unit
``normal`` pointing up into the room and an ``offset`` (m) with ``normal @ p + offset = 0`` on
the floor; ``offset`` is then the camera's height above it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmpose.core.errors import ConfigError, ShapeError
from swarmpose.core.rotations import matrix_to_quaternion, quaternion_multiply

RIGID_TOLERANCE = 1e-3
"""A given rotation may differ from an orthonormal one (det +1) by this much per entry."""
EXTRINSICS_FORMS = ('{"camera_to_world": [[4 x 4]]}', '{"floor": {"normal": [nx, ny, nz], "offset_m": d}}',
                    '{"camera_height_m": h, "pitch_deg": p, "roll_deg": r}')


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def foot_point(normal: np.ndarray, offset: float, point: np.ndarray) -> np.ndarray:
    """The point (3,) on the plane ``normal @ p + offset = 0`` straight below (or above) ``point`` (3,)."""
    n = np.asarray(normal, dtype=np.float64)
    p = np.asarray(point, dtype=np.float64)
    return p - (n @ p + offset) * n


def world_from_floor(normal: np.ndarray, offset: float, origin: np.ndarray | None = None) -> np.ndarray:
    """The camera-to-world transform (4, 4) of the floor ``normal`` (3,) (unit, up, camera frame)
    and ``offset`` (m), the world origin at the floor point below camera-frame point ``origin``
    (3,) m (None: below the camera). Axes as in the module docstring; where the camera's x axis
    is (nearly) perpendicular to the floor, its z axis projected onto the floor gives x instead."""
    n = _unit(np.asarray(normal, dtype=np.float64))
    x = None
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])):
        along = axis - (axis @ n) * n
        if np.linalg.norm(along) > 1e-3:
            x = _unit(along)
            break
    z = np.cross(x, n)
    rotation = np.stack([x, n, z])
    anchor = foot_point(n, offset, np.zeros(3) if origin is None else origin)
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = -rotation @ anchor
    return out


def floor_of(camera_to_world: np.ndarray) -> tuple[np.ndarray, float]:
    """The floor (world ``y = 0``) of a camera-to-world transform (4, 4): its unit up normal (3,)
    in the camera frame and its offset (m)."""
    t = np.asarray(camera_to_world, dtype=np.float64)
    return t[1, :3].copy(), float(t[1, 3])


def camera_angles(normal: np.ndarray) -> tuple[float, float]:
    """(pitch, roll) in degrees of a camera over a floor with up ``normal`` (3,) (camera frame):
    pitch > 0 when the optical axis points below the horizon, ``asin(-n_z)``; roll
    ``atan2(n_x, -n_y)``, > 0 when the floor's up leans towards the image's right."""
    n = _unit(np.asarray(normal, dtype=np.float64))
    return math.degrees(math.asin(float(np.clip(-n[2], -1.0, 1.0)))), math.degrees(math.atan2(n[0], -n[1]))


def normal_of_angles(pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """The floor's up normal (3,) in the camera frame of a camera pitched ``pitch_deg`` down and
    rolled ``roll_deg`` (the inverse of :func:`camera_angles`)."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    return np.array([math.cos(p) * math.sin(r), -math.cos(p) * math.cos(r), -math.sin(p)])


def transform_points(camera_to_world: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) m mapped by a (4, 4) transform (NaN rows stay NaN)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-1:] != (3,):
        raise ShapeError(f"points has shape {pts.shape}, expected (..., 3)")
    t = np.asarray(camera_to_world, dtype=np.float64)
    return pts @ t[:3, :3].T + t[:3, 3]


def transform_poses(camera_to_world: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses h (..., 36) (root position m, root quaternion wxyz, 29 angles) mapped by a (4, 4)
    rigid transform: the root moves as a point, the root rotation is turned by ``R``, the joint
    angles (relative to the root) stay."""
    h = np.array(poses, dtype=np.float64)
    if h.ndim == 0 or h.shape[-1] < 7:
        raise ShapeError(f"poses has shape {h.shape}, expected (..., 36)")
    t = np.asarray(camera_to_world, dtype=np.float64)
    flat = h.reshape(-1, h.shape[-1])
    flat[:, 0:3] = transform_points(t, flat[:, 0:3])
    flat[:, 3:7] = quaternion_multiply(matrix_to_quaternion(t[:3, :3]), flat[:, 3:7])
    return flat.reshape(h.shape)


def check_rigid(matrix, name: str) -> np.ndarray:
    """``matrix`` as a (4, 4) rigid transform (rotation with det +1, last row 0 0 0 1, finite);
    ConfigError naming ``name`` otherwise. The rotation is re-orthonormalised (SVD)."""
    try:
        t = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: camera_to_world must be 4 rows of 4 numbers") from None
    if t.shape != (4, 4) or not np.all(np.isfinite(t)):
        raise ConfigError(f"{name}: camera_to_world must be 4 rows of 4 finite numbers, got shape {t.shape}")
    if np.max(np.abs(t[3] - [0.0, 0.0, 0.0, 1.0])) > RIGID_TOLERANCE:
        raise ConfigError(f"{name}: the last row of camera_to_world must be [0, 0, 0, 1], got {t[3].tolist()}")
    r = t[:3, :3]
    if np.max(np.abs(r @ r.T - np.eye(3))) > RIGID_TOLERANCE or np.linalg.det(r) < 0:
        raise ConfigError(f"{name}: the upper-left 3x3 of camera_to_world is not a rotation (orthonormal, "
                          "det +1); give metres and a rotation, no scale or mirror")
    u, _, vt = np.linalg.svd(r)
    out = t.copy()
    out[:3, :3] = u @ vt
    out[3] = [0.0, 0.0, 0.0, 1.0]
    return out


@dataclass(frozen=True, eq=False)
class WorldState:
    """What is known of the world frame of one camera.

    floor_normal: (3,) unit up normal, camera frame; floor_offset_m: the camera's height above
    the floor (m); source: ``"depth"`` (fitted) or ``"extrinsics"`` (given); inliers: the fit's
    RANSAC inliers (0 when given); camera_to_world: (4, 4) once the origin is known, else None.
    """

    floor_normal: np.ndarray
    floor_offset_m: float
    source: str
    inliers: int = 0
    camera_to_world: np.ndarray | None = None

    def as_dict(self) -> dict:
        """JSON-friendly: ``floor`` (normal, offset_m, source, inliers, camera_height_m, pitch_deg,
        roll_deg) and ``camera_to_world`` (4 rows of 4 or None)."""
        pitch, roll = camera_angles(self.floor_normal)
        floor = {"normal": [round(float(v), 6) for v in self.floor_normal],
                 "offset_m": round(float(self.floor_offset_m), 6), "source": self.source,
                 "inliers": int(self.inliers), "camera_height_m": round(float(self.floor_offset_m), 4),
                 "pitch_deg": round(pitch, 3), "roll_deg": round(roll, 3)}
        return {"floor": floor, "camera_to_world": matrix_rows(self.camera_to_world)}


def matrix_rows(matrix: np.ndarray | None, digits: int = 6) -> list[list[float]] | None:
    """A (4, 4) matrix as 4 JSON rows rounded to ``digits``, or None."""
    if matrix is None:
        return None
    return [[round(float(v), digits) + 0.0 for v in row] for row in np.asarray(matrix)]


def _number(value, name: str, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{name}: {what} must be a finite number, got {value!r}")
    return float(value)


def _floor_state(name: str, normal, offset) -> WorldState:
    if not isinstance(normal, (list, tuple)) or len(normal) != 3:
        raise ConfigError(f"{name}: floor.normal must be a list of 3 numbers (camera frame, pointing up)")
    n = np.array([_number(v, name, "each entry of floor.normal") for v in normal])
    length = float(np.linalg.norm(n))
    if length < 1e-6:
        raise ConfigError(f"{name}: floor.normal is zero; give the floor's up direction in the camera frame")
    d = _number(offset, name, "floor.offset_m") / length
    n = n / length
    if d <= 0:
        raise ConfigError(f"{name}: floor.offset_m must be the camera's height above the floor (> 0) with the "
                          f"normal pointing up into the room; got {d:g} (if the normal points down, negate both)")
    return WorldState(n, d, "extrinsics")


def parse_extrinsics(data, name: str) -> WorldState:
    """The world state of an extrinsics object (one of :data:`EXTRINSICS_FORMS`); ConfigError
    naming ``name`` when it is none of them or holds bad values."""
    if not isinstance(data, dict):
        raise ConfigError(f"{name}: extrinsics must be a JSON object, one of {' or '.join(EXTRINSICS_FORMS)}")
    if "camera_to_world" in data:
        t = check_rigid(data["camera_to_world"], name)
        normal, offset = floor_of(t)
        if offset <= 0:
            raise ConfigError(f"{name}: camera_to_world puts the camera {offset:g} m above the floor (world y = 0); "
                              "the world frame is y up with the floor at y = 0, the camera above it")
        return WorldState(normal, offset, "extrinsics", camera_to_world=t)
    if "floor" in data:
        floor = data["floor"]
        if not isinstance(floor, dict) or not {"normal", "offset_m"} <= set(floor):
            raise ConfigError(f"{name}: floor must be an object with normal and offset_m, e.g. "
                              '{"floor": {"normal": [0, -0.97, -0.26], "offset_m": 1.2}}')
        return _floor_state(name, floor["normal"], floor["offset_m"])
    if "camera_height_m" in data:
        height = _number(data["camera_height_m"], name, "camera_height_m")
        pitch = _number(data.get("pitch_deg", 0.0), name, "pitch_deg")
        roll = _number(data.get("roll_deg", 0.0), name, "roll_deg")
        if not (-90.0 < pitch < 90.0 and -90.0 < roll < 90.0):
            raise ConfigError(f"{name}: pitch_deg and roll_deg must lie within -90..90, got {pitch:g}, {roll:g}")
        return _floor_state(name, normal_of_angles(pitch, roll).tolist(), height)
    raise ConfigError(f"{name}: no extrinsics found (keys {sorted(data)}); give one of "
                      f"{' or '.join(EXTRINSICS_FORMS)}")


def load_extrinsics(path: str | Path) -> WorldState:
    """The world state of an extrinsics JSON file (see :func:`parse_extrinsics`); ConfigError
    naming the file when it is missing, not JSON or malformed."""
    p = Path(path)
    try:
        text = p.read_text("utf-8")
    except FileNotFoundError:
        raise ConfigError(f"extrinsics file {p} not found; pass --floor auto, off or an existing JSON file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"extrinsics file {p} cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ConfigError(f"extrinsics file {p} is not JSON ({exc}); give one of "
                          f"{' or '.join(EXTRINSICS_FORMS)}") from None
    return parse_extrinsics(data, f"extrinsics file {p}")


__all__ = ["EXTRINSICS_FORMS", "WorldState", "camera_angles", "check_rigid", "floor_of", "foot_point",
           "load_extrinsics", "matrix_rows", "normal_of_angles", "parse_extrinsics", "transform_points",
           "transform_poses", "world_from_floor"]
