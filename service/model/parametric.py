"""The built-in parametric body: a smooth skinned human generated from a few numbers.

The body is the zero level set of a signed-distance field (SDF): a smooth union of
per-segment primitives (ellipsoidal head, lofted elliptical torso, tapered capsules for
the neck and limbs, rounded-box hands, ellipsoidal feet cut flat at the floor). The field
is sampled on a regular grid, meshed with marching cubes, oriented outward and decimated
to about :data:`TARGET_TRIANGLES` triangles. Skin weights come from the same primitives:
a softmax over bones of ``-sdf / tau``, so weights blend smoothly across joints.

Proportions follow anthropometric tables (segment lengths as fractions of stature, in the
style of Drillis & Contini), written below in metres for a 1.75 m reference person and
scaled by ``height / 1.75``. The body stands in the body frame (X = subject's left,
Y = up, Z = forward; metres) in an A-pose: arms 45 degrees below horizontal in the
frontal plane, palms facing the thighs, legs slightly apart, feet pointing along +Z.
Every output is shifted so that the pelvis (midpoint of the hip joints) is the origin.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, fields

import numpy as np

from ..errors import ConfigError
from .body import SkinnedBody, body_frame_bind_matrices, sparse_skin
from .landmarks import face_landmarks, foot_landmarks
from .skeleton import JOINT_INDEX, POINT_NAMES

REFERENCE_HEIGHT = 1.75
"""Stature (m) the construction constants below are written for."""
TARGET_TRIANGLES = 12_000
BLEND = 0.025
"""Smooth-union blend radius, m (at the reference height)."""
SKIN_TAU = 0.015
"""Softmax temperature of the skin weights, m of signed distance."""
TORSO_SKIN_SOFTNESS = 0.5
"""Scale on the height distance between torso bands: < 1 widens the spine blends."""
ARM_DROP = np.deg2rad(45.0)
"""A-pose: angle of the arms below horizontal, rad."""

HEIGHT_RANGE = (1.2, 2.3)
GIRTH_RANGE = (0.5, 2.0)
SEXES = ("neutral", "male", "female")

BONES: tuple[tuple[str, str | None, str | None, float], ...] = (
    # (bone, parent, tracking joint or None = rigid, share of the joint's angles)
    ("pelvis", None, None, 1.0),
    ("spine_lower", "pelvis", "spine", 0.5),
    ("spine_upper", "spine_lower", "spine", 0.5),
    ("neck", "spine_upper", "neck", 1.0),
    ("head", "neck", None, 1.0),
    ("left_clavicle", "spine_upper", "left_collar", 1.0),
    ("right_clavicle", "spine_upper", "right_collar", 1.0),
    ("left_upper_arm", "left_clavicle", "left_shoulder", 1.0),
    ("right_upper_arm", "right_clavicle", "right_shoulder", 1.0),
    ("left_forearm", "left_upper_arm", "left_elbow", 1.0),
    ("right_forearm", "right_upper_arm", "right_elbow", 1.0),
    ("left_hand", "left_forearm", None, 1.0),
    ("right_hand", "right_forearm", None, 1.0),
    ("left_thigh", "pelvis", "left_hip", 1.0),
    ("right_thigh", "pelvis", "right_hip", 1.0),
    ("left_shin", "left_thigh", "left_knee", 1.0),
    ("right_shin", "right_thigh", "right_knee", 1.0),
    ("left_foot", "left_shin", "left_ankle", 1.0),
    ("right_foot", "right_shin", "right_ankle", 1.0),
)
BONE_NAMES = tuple(b[0] for b in BONES)
BONE_INDEX = {n: i for i, n in enumerate(BONE_NAMES)}

# Torso loft at the reference height: (y, half-width, half-depth, z of the centre), m.
_TORSO = np.array([
    (0.785, 0.040, 0.054, -0.010),
    (0.820, 0.110, 0.097, -0.015),
    (0.870, 0.160, 0.117, -0.018),
    (0.930, 0.170, 0.124, -0.015),
    (1.000, 0.158, 0.117, -0.005),
    (1.080, 0.140, 0.108, 0.000),
    (1.170, 0.146, 0.114, 0.004),
    (1.250, 0.156, 0.125, 0.004),
    (1.330, 0.165, 0.130, 0.000),
    (1.385, 0.166, 0.119, -0.010),
    (1.425, 0.135, 0.095, -0.020),
    (1.450, 0.090, 0.073, -0.025),
    (1.470, 0.055, 0.059, -0.025),
])
# Per sex: multipliers on the torso half-width at the hips (y < 1.0 m) and chest
# (y > 1.2 m), on the shoulder and hip joint spread, and on every girth.
_SEX = {
    "neutral": {"hips": 1.00, "chest": 1.00, "shoulders": 1.00, "hip_joints": 1.00, "girth": 1.00},
    "male": {"hips": 0.95, "chest": 1.05, "shoulders": 1.05, "hip_joints": 0.96, "girth": 1.02},
    "female": {"hips": 1.08, "chest": 0.95, "shoulders": 0.93, "hip_joints": 1.06, "girth": 0.97},
}


# ---------------------------------------------------------------------------- shape
@dataclass(frozen=True)
class BodyShape:
    """Personalisation of the built-in body.

    height: stature in metres (1.2..2.3). torso_girth / arm_girth / leg_girth:
    multiplicative factors (0.5..2.0) on the cross-section radii of the torso (and
    neck), the arms and the legs. sex: "neutral", "male" (broader shoulders, narrower
    hips) or "female" (narrower shoulders, wider hips, slightly smaller girths).
    """

    height: float = 1.75
    torso_girth: float = 1.0
    arm_girth: float = 1.0
    leg_girth: float = 1.0
    sex: str = "neutral"

    def __post_init__(self) -> None:
        for name in ("height", "torso_girth", "arm_girth", "leg_girth"):
            try:
                object.__setattr__(self, name, float(getattr(self, name)))
            except (TypeError, ValueError):
                raise ConfigError(f"body {name} {getattr(self, name)!r} is not a number") from None
        lo, hi = HEIGHT_RANGE
        if not lo <= self.height <= hi:
            raise ConfigError(f"body height {self.height} m is outside the allowed range {lo}..{hi} m")
        lo, hi = GIRTH_RANGE
        for name in ("torso_girth", "arm_girth", "leg_girth"):
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise ConfigError(f"body {name} {value} is outside the allowed range {lo}..{hi}")
        if self.sex not in SEXES:
            raise ConfigError(f"body sex {self.sex!r} is not one of {', '.join(SEXES)}")


BUILTIN_PRESETS: dict[str, BodyShape] = {
    "default": BodyShape(),
    "male": BodyShape(height=1.78, sex="male"),
    "female": BodyShape(height=1.65, sex="female"),
    "male-heavy": BodyShape(height=1.78, torso_girth=1.35, arm_girth=1.25, leg_girth=1.25, sex="male"),
    "female-slim": BodyShape(height=1.68, torso_girth=0.9, arm_girth=0.88, leg_girth=0.9, sex="female"),
    "male-tall": BodyShape(height=1.93, sex="male"),
    "female-short": BodyShape(height=1.56, sex="female"),
}

_SHAPE_KEYS = {"height": "height", "torso": "torso_girth", "arms": "arm_girth", "legs": "leg_girth", "sex": "sex"}
_SHAPE_KEYS.update({f.name: f.name for f in fields(BodyShape)})


def parse_shape(spec: str) -> BodyShape:
    """A :class:`BodyShape` from a preset name, ``key=value,...`` or a preset then overrides.

    Examples: ``"male-tall"``, ``"height=1.82,torso=1.1,arms=0.9,legs=1.0,sex=male"``,
    ``"female,height=1.60"``. Keys: height, torso, arms, legs, sex (or the field names).
    An empty spec is the default body. Raises :class:`ConfigError` on unknown presets,
    keys or values out of range.
    """
    items = [s.strip() for s in str(spec).split(",") if s.strip()]
    base = BUILTIN_PRESETS["default"]
    if items and "=" not in items[0]:
        name = items.pop(0)
        if name not in BUILTIN_PRESETS:
            raise ConfigError(f"unknown body preset {name!r}; valid presets: {', '.join(BUILTIN_PRESETS)}")
        base = BUILTIN_PRESETS[name]
    values = asdict(base)
    for item in items:
        key, sep, raw = (s.strip() for s in item.partition("="))
        if not sep or key not in _SHAPE_KEYS:
            raise ConfigError(f"bad body shape item {item!r} in {spec!r}: expected key=value with key one of "
                              f"{', '.join(_SHAPE_KEYS)}; a preset name ({', '.join(BUILTIN_PRESETS)}) "
                              "may only come first")
        field_name = _SHAPE_KEYS[key]
        if field_name == "sex":
            values[field_name] = raw
        else:
            try:
                values[field_name] = float(raw)
            except ValueError:
                raise ConfigError(f"body shape {key}={raw!r} is not a number") from None
    return BodyShape(**values)


def preset_name(shape: BodyShape) -> str | None:
    """The name of the preset equal to ``shape``, or None."""
    return next((n for n, s in BUILTIN_PRESETS.items() if s == shape), None)


# ---------------------------------------------------------------------------- primitives
def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance fields, blend radius ``k``."""
    h = np.maximum(k - np.abs(a - b), 0.0) / k
    return np.minimum(a, b) - 0.25 * k * h * h


@dataclass(frozen=True)
class _Part:
    """A primitive with its bone. ``kind``: ellipsoid, cone or box; ``frame`` rows = local axes."""

    bone: str
    kind: str
    centre: np.ndarray  # (3,) ellipsoid/box centre, cone start
    size: np.ndarray  # ellipsoid/box half-extents (3,), cone (end x, y, z, r0, r1)
    frame: np.ndarray | None = None  # (3, 3) rows = local axes, for rotated boxes/ellipsoids
    rounding: float = 0.0

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance estimate (N,) m of points (N, 3) m; negative inside."""
        q = p - self.centre
        if self.frame is not None:
            q = q @ self.frame.T
        if self.kind == "ellipsoid":
            r = self.size
            k0 = np.linalg.norm(q / r, axis=1)
            k1 = np.maximum(np.linalg.norm(q / (r * r), axis=1), 1e-12)
            return k0 * (k0 - 1.0) / k1
        if self.kind == "box":
            d = np.abs(q) - (self.size - self.rounding)
            outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
            return outside + np.minimum(d.max(axis=1), 0.0) - self.rounding
        if self.kind == "cone":  # capsule whose radius varies linearly from r0 to r1
            axis, r0, r1 = self.size[:3] - self.centre, self.size[3], self.size[4]
            t = np.clip(q @ axis / (axis @ axis), 0.0, 1.0)
            return np.linalg.norm(q - t[:, None] * axis, axis=1) - (r0 + (r1 - r0) * t)
        raise ValueError(self.kind)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo, hi) (3,) each, m, containing the part."""
        if self.kind == "cone":
            end, r = self.size[:3], max(self.size[3], self.size[4])
            return np.minimum(self.centre, end) - r, np.maximum(self.centre, end) + r
        reach = np.linalg.norm(self.size) if self.frame is not None else self.size
        return self.centre - reach, self.centre + reach


@dataclass(frozen=True)
class _Torso:
    """Lofted torso: elliptical sections (half-width a, half-depth b, centre z) along y."""

    keys: np.ndarray  # (K, 4) y, a, b, c

    def profile(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from scipy.interpolate import PchipInterpolator

        yy = np.clip(y, self.keys[0, 0], self.keys[-1, 0])
        return tuple(PchipInterpolator(self.keys[:, 0], self.keys[:, i])(yy) for i in (1, 2, 3))

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """First-order distance estimate (N,) to the loft surface, capped at both ends."""
        a, b, c = self.profile(p[:, 1])
        u, v = p[:, 0] / a, (p[:, 2] - c) / b
        k = np.hypot(u, v)
        grad = np.maximum(np.hypot(u / a, v / b), 1e-12) / np.maximum(k, 1e-12)
        grad = np.where(k < 1e-9, 1.0 / np.maximum(a, b), grad)
        radial = (k - 1.0) / grad
        caps = np.maximum(self.keys[0, 0] - p[:, 1], p[:, 1] - self.keys[-1, 0])
        return np.maximum(radial, caps)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        ks = self.keys
        return (np.array([-ks[:, 1].max(), ks[0, 0], (ks[:, 3] - ks[:, 2]).min()]),
                np.array([ks[:, 1].max(), ks[-1, 0], (ks[:, 3] + ks[:, 2]).max()]))


# ---------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class _Layout:
    """Everything the construction decides, in the floor frame (soles at y = 0), m."""

    heads: np.ndarray  # (B, 3) bone heads
    points: dict  # name -> (3,) exact named points (joints and eyes)
    parts: tuple  # _Part/_Torso primitives
    torso_bands: tuple[float, float]  # y of the pelvis/spine_lower and spine_lower/spine_upper splits
    scale: float


def _layout(shape: BodyShape) -> _Layout:
    """Joints and primitives of ``shape`` in the floor frame.

    Reference proportions (fractions of stature H): hip joints 0.53 H, knees 0.285 H,
    ankles 0.039 H, shoulder joints 0.80 H, base of the neck 0.83 H, skull base 0.90 H,
    eyes 0.94 H; upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, foot 0.15 H long.
    """
    s = shape.height / REFERENCE_HEIGHT
    sx = _SEX[shape.sex]
    tg, ag, lg = (g * sx["girth"] for g in (shape.torso_girth, shape.arm_girth, shape.leg_girth))
    v = lambda *xyz: np.array(xyz, dtype=np.float64) * s  # reference metres -> this body

    torso = _TORSO.copy()
    sex_width = np.where(torso[:, 0] < 1.0, sx["hips"], np.where(torso[:, 0] > 1.2, sx["chest"], 1.0))
    torso[:, 1] *= sex_width * tg
    torso[:, 2] *= tg
    torso *= s
    shoulder_x = (0.175 * sx["shoulders"] + 0.5 * 0.168 * (shape.torso_girth - 1.0)) * s
    hip_x = 0.085 * sx["hip_joints"] * s

    j: dict[str, np.ndarray] = {
        "pelvis": v(0.0, 0.925, 0.0), "spine_lower": v(0.0, 1.05, -0.035), "spine_upper": v(0.0, 1.25, -0.05),
        "neck": v(0.0, 1.45, -0.03), "head": v(0.0, 1.575, -0.01),
    }
    arm = np.array([np.cos(ARM_DROP), -np.sin(ARM_DROP), 0.0])
    parts: list = [_Torso(torso)]
    for side, sign in (("left", 1.0), ("right", -1.0)):
        mirror = np.array([sign, 1.0, 1.0])
        d = arm * mirror
        clav = v(sign * 0.025, 1.405, 0.005)  # clavicle ~horizontal: collar rest angles within Table 1
        sh = np.array([sign * shoulder_x, 1.395 * s, -0.005 * s])
        el = sh + d * 0.325 * s
        wr = el + d * 0.256 * s
        hip = np.array([sign * hip_x, 0.925 * s, 0.0])
        ank = v(sign * 0.10, 0.068, 0.0)
        knee = hip + (ank - hip) * (hip[1] - 0.499 * s) / (hip[1] - ank[1])
        j.update({f"{side}_clavicle": clav, f"{side}_upper_arm": sh, f"{side}_forearm": el,
                  f"{side}_hand": wr, f"{side}_thigh": hip, f"{side}_shin": knee, f"{side}_foot": ank})
        hand_frame = np.stack([d, np.cross(d, [0.0, 0.0, 1.0]), [0.0, 0.0, 1.0]])
        cone = lambda bone, a, b, r0, r1: _Part(bone, "cone", a, np.r_[b, r0, r1])
        parts += [
            cone(f"{side}_clavicle", clav, sh - d * 0.02 * s, 0.045 * s * tg, 0.048 * s * ag),
            cone(f"{side}_upper_arm", sh, el, 0.050 * s * ag, 0.038 * s * ag),
            cone(f"{side}_forearm", el, wr, 0.039 * s * ag, 0.027 * s * ag),
            _Part(f"{side}_hand", "box", wr + d * 0.092 * s, v(0.092, 0.015 * ag, 0.042 * ag), hand_frame, 0.012 * s),
            cone(f"{side}_thigh", hip + v(sign * 0.015, -0.02, -0.005), knee, 0.090 * s * lg, 0.053 * s * lg),
            cone(f"{side}_shin", knee, ank, 0.050 * s * lg, 0.033 * s * lg),
            _Part(f"{side}_shin", "ellipsoid", knee + (ank - knee) * 0.3 + v(0.0, 0.0, -0.02),
                  v(0.047 * lg, 0.10, 0.050 * lg)),
            _Part(f"{side}_foot", "ellipsoid", np.array([ank[0], 0.03 * s, 0.065 * s]), v(0.045, 0.055, 0.13)),
        ]
    neck_r = 0.058 * s * sx["girth"] * (1.0 + 0.5 * (shape.torso_girth - 1.0))
    parts += [
        _Part("neck", "cone", v(0.0, 1.42, -0.025), np.r_[v(0.0, 1.58, -0.008), neck_r, neck_r]),
        _Part("head", "ellipsoid", v(0.0, 1.655, 0.0), v(0.0775, 0.095, 0.0975)),
        _Part("head", "ellipsoid", v(0.0, 1.585, 0.03), v(0.058, 0.07, 0.068)),
        _Part("head", "ellipsoid", v(0.0, 1.62, 0.093), v(0.014, 0.028, 0.02)),
    ]
    crown = 1.655 * s + 0.095 * s
    eye_y, eye_x = 1.645 * s, 0.032 * s
    eye_z = 0.0975 * s * np.sqrt(1.0 - (eye_x / (0.0775 * s)) ** 2 - ((eye_y - 1.655 * s) / (0.095 * s)) ** 2)
    points = {
        "head": np.array([0.0, 0.5 * (j["head"][1] + crown), 0.0]),
        "left_eye": np.array([eye_x, eye_y, eye_z - 0.004 * s]),
        "right_eye": np.array([-eye_x, eye_y, eye_z - 0.004 * s]),
    }
    heads = np.stack([j[n] for n in BONE_NAMES])
    return _Layout(heads, points, tuple(parts), (j["spine_lower"][1], j["spine_upper"][1]), s)


# ---------------------------------------------------------------------------- meshing
def _field(layout: _Layout, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample the body SDF on a grid: returns (values (nx, ny, nz), origin (3,)), m."""
    k = BLEND * layout.scale
    lo = np.min([p.bounds()[0] for p in layout.parts], axis=0) - 3 * resolution - k
    hi = np.max([p.bounds()[1] for p in layout.parts], axis=0) + 3 * resolution + k
    lo[1] = -3 * resolution
    lo = np.floor(lo / resolution) * resolution
    n = np.ceil((hi - lo) / resolution).astype(int) + 1
    axes = [lo[i] + resolution * np.arange(n[i]) for i in range(3)]
    far = 1.0
    values = np.full(tuple(n), far)
    for part in layout.parts:
        plo, phi = part.bounds()
        i0 = np.clip(np.floor((plo - k - 2 * resolution - lo) / resolution).astype(int), 0, n - 1)
        i1 = np.clip(np.ceil((phi + k + 2 * resolution - lo) / resolution).astype(int) + 1, 1, n)
        block = tuple(slice(a, b) for a, b in zip(i0, i1, strict=True))
        grid = np.stack(np.meshgrid(*(ax[sl] for ax, sl in zip(axes, block, strict=True)), indexing="ij"), -1)
        d = part.sdf(grid.reshape(-1, 3)).reshape(grid.shape[:3])
        values[block] = _smin(values[block], np.minimum(d, far), k)
    values = np.maximum(values, -axes[1][None, :, None])  # flat soles: cut at the floor y = 0
    return values, lo


def _mesh(values: np.ndarray, origin: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes + outward orientation + quadric decimation -> (V, 3) m, (F, 3) int32."""
    import open3d as o3d
    from skimage.measure import marching_cubes

    verts, faces, _, _ = marching_cubes(values, 0.0, spacing=(resolution,) * 3, allow_degenerate=False)
    verts = verts + origin
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts), o3d.utility.Vector3iVector(faces))
    if len(faces) > TARGET_TRIANGLES:
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=TARGET_TRIANGLES)
    mesh.remove_degenerate_triangles()
    mesh.remove_unreferenced_vertices()
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.triangles, dtype=np.int32)
    if _signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def _signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume (m^3) enclosed by triangles; > 0 when they wind counter-clockwise outside."""
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _skin(layout: _Layout, verts: np.ndarray) -> np.ndarray:
    """Dense skin weights (V, B): softmax over bones of -sdf / tau at the rest vertices."""
    tau = SKIN_TAU * layout.scale
    dist = np.full((len(verts), len(BONE_NAMES)), np.inf)
    y = verts[:, 1]
    split_lo, split_hi = layout.torso_bands
    for part in layout.parts:
        d = part.sdf(verts)
        if isinstance(part, _Torso):  # one loft, three bones: bands split at the spine pivots
            outside = (("pelvis", y - split_lo), ("spine_lower", np.maximum(split_lo - y, y - split_hi)),
                       ("spine_upper", split_hi - y))
            for bone, o in outside:
                b = BONE_INDEX[bone]
                dist[:, b] = np.minimum(dist[:, b], np.maximum(d, TORSO_SKIN_SOFTNESS * o))
        else:
            b = BONE_INDEX[part.bone]
            dist[:, b] = np.minimum(dist[:, b], d)
    logits = -(dist - dist.min(axis=1, keepdims=True)) / tau
    w = np.exp(logits)
    return w / w.sum(axis=1, keepdims=True)


# ---------------------------------------------------------------------------- body
@functools.lru_cache(maxsize=16)
def build_parametric_body(shape: BodyShape = BodyShape(), resolution: float = 0.01) -> SkinnedBody:
    """The built-in skinned body for ``shape``, meshed on a grid of ``resolution`` metres.

    Returns a :class:`SkinnedBody` with about 12,000 triangles (fewer for coarse grids),
    19 bones (:data:`BONE_NAMES`), every named point of ``POINT_NAMES``, the pelvis at the
    origin. Deterministic and memoised on ``(shape, resolution)``: callers share the
    instance and must not modify its arrays in place (copy them first).
    """
    if not 0.003 <= float(resolution) <= 0.03:
        raise ConfigError(f"body mesh resolution {resolution} m is outside the allowed range 0.003..0.03 m")
    layout = _layout(shape)
    values, origin = _field(layout, float(resolution))
    verts, faces = _mesh(values, origin, float(resolution))
    weights = _skin(layout, verts)
    skin_indices, skin_weights = sparse_skin(weights, len(verts))

    root = layout.heads[0].copy()
    verts = verts - root
    heads = layout.heads - root
    exact = {n: p - root for n, p in layout.points.items()}
    bone_of = {"upper_arm": "shoulder", "forearm": "elbow", "hand": "wrist", "thigh": "hip", "shin": "knee",
               "foot": "ankle", "clavicle": "clavicle"}
    carriers: dict[str, str] = {"head": "head", "left_eye": "head", "right_eye": "head", "neck": "neck",
                                "mid_hip": "pelvis", "spine": "spine_lower"}
    exact.update({"neck": heads[BONE_INDEX["neck"]], "mid_hip": heads[0], "spine": heads[BONE_INDEX["spine_lower"]]})
    for side in ("left", "right"):
        for bone, point in bone_of.items():
            exact[f"{side}_{point}"] = heads[BONE_INDEX[f"{side}_{bone}"]]
            carriers[f"{side}_{point}"] = f"{side}_{bone}"
    face = face_landmarks(verts, exact["head"], exact["neck"], (exact["left_eye"], exact["right_eye"]))
    feet = foot_landmarks(verts, exact["left_ankle"], exact["right_ankle"])
    for name in ("nose", "left_ear", "right_ear"):
        exact[name], carriers[name] = face[name], "head"
    for name, pos in feet.items():
        exact[name], carriers[name] = pos, name.split("_")[0] + "_foot"

    parents = np.array([BONE_INDEX[p] if p else -1 for _, p, _, _ in BONES], dtype=np.int64)
    bone_joint = np.array([JOINT_INDEX[jn] if jn else -1 for _, _, jn, _ in BONES], dtype=np.int64)
    preset = preset_name(shape)
    body = SkinnedBody(
        name="builtin" if preset in (None, "default") else f"builtin:{preset}",
        vertices=verts, triangles=faces, skin_indices=skin_indices, skin_weights=skin_weights,
        bone_names=BONE_NAMES, bone_parents=parents, bone_heads=heads,
        bind_matrices=body_frame_bind_matrices(heads), bone_joint=bone_joint,
        bone_fraction=np.array([f for *_, f in BONES], dtype=np.float64),
        point_names=POINT_NAMES,
        point_bones=np.array([BONE_INDEX[carriers[p]] for p in POINT_NAMES], dtype=np.int64),
        point_rest=np.stack([exact[p] for p in POINT_NAMES]).astype(np.float64),
        metadata={"source": "builtin", "shape": asdict(shape), "resolution": float(resolution)},
    )
    return body
