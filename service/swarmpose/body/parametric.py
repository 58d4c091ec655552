"""The built-in parametric body: a smooth skinned human generated from a few numbers.

The body is the zero level set of a signed-distance field (SDF): a smooth union of
per-segment primitives (ellipsoidal head, lofted elliptical torso, tapered capsules for
the neck and limbs, rounded-box hands, ellipsoidal feet cut flat at the floor). The field
is sampled on a regular grid, meshed with marching cubes, oriented outward and decimated
to about :data:`TARGET_TRIANGLES` triangles (primitives and meshing:
:mod:`swarmpose.body.parametric_sdf`). Skin weights come from the same primitives:
a softmax over bones of ``-sdf / tau``, so weights blend smoothly across joints.

Proportions follow anthropometric tables (segment lengths as fractions of stature, in the
style of Drillis & Contini), written below in metres for a 1.75 m reference person and
scaled by ``height / 1.75``. The body stands in the body frame (X = subject's left,
Y = up, Z = forward; metres) in an A-pose: arms 45 degrees below horizontal in the
frontal plane, palms facing the thighs, legs slightly apart, feet pointing along +Z.
Every output is shifted so that the pelvis (midpoint of the hip joints) is the origin.
The shape parameters and presets are :mod:`swarmpose.body.parametric_shape`.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from importlib.metadata import version
from pathlib import Path

import numpy as np

from swarmpose.body.landmarks import face_landmarks, foot_landmarks
from swarmpose.body.parametric_sdf import Part, Torso, mesh_field, sample_field
from swarmpose.body.parametric_shape import BodyShape, preset_name
from swarmpose.body.skeleton import JOINT_INDEX, POINT_NAMES
from swarmpose.body.skinned import SkinnedBody, body_frame_bind_matrices, sparse_skin
from swarmpose.core.cache import cache_key, cached_arrays
from swarmpose.core.errors import ConfigError

REFERENCE_HEIGHT = 1.75
"""Stature (m) the construction constants below are written for."""
TARGET_TRIANGLES = 12_000
"""Triangle count the marching-cubes mesh is decimated to."""
BLEND = 0.025
"""Smooth-union blend radius, m (at the reference height)."""
SKIN_TAU = 0.015
"""Softmax temperature of the skin weights, m of signed distance."""
TORSO_SKIN_SOFTNESS = 0.5
"""Scale on the height distance between torso bands: < 1 widens the spine blends."""
ARM_DROP = np.deg2rad(45.0)
"""A-pose: angle of the arms below horizontal, rad."""

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


# ---------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class _Layout:
    """Everything the construction decides, in the floor frame (soles at y = 0), m."""

    heads: np.ndarray  # (B, 3) bone heads
    points: dict  # name -> (3,) exact named points (joints and eyes)
    parts: tuple  # Part/Torso primitives
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
    parts: list = [Torso(torso)]
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
        cone = lambda bone, a, b, r0, r1: Part(bone, "cone", a, np.r_[b, r0, r1])
        parts += [
            cone(f"{side}_clavicle", clav, sh - d * 0.02 * s, 0.045 * s * tg, 0.048 * s * ag),
            cone(f"{side}_upper_arm", sh, el, 0.050 * s * ag, 0.038 * s * ag),
            cone(f"{side}_forearm", el, wr, 0.039 * s * ag, 0.027 * s * ag),
            Part(f"{side}_hand", "box", wr + d * 0.092 * s, v(0.092, 0.015 * ag, 0.042 * ag), hand_frame, 0.012 * s),
            cone(f"{side}_thigh", hip + v(sign * 0.015, -0.02, -0.005), knee, 0.090 * s * lg, 0.053 * s * lg),
            cone(f"{side}_shin", knee, ank, 0.050 * s * lg, 0.033 * s * lg),
            Part(f"{side}_shin", "ellipsoid", knee + (ank - knee) * 0.3 + v(0.0, 0.0, -0.02),
                  v(0.047 * lg, 0.10, 0.050 * lg)),
            Part(f"{side}_foot", "ellipsoid", np.array([ank[0], 0.03 * s, 0.065 * s]), v(0.045, 0.055, 0.13)),
        ]
    neck_r = 0.058 * s * sx["girth"] * (1.0 + 0.5 * (shape.torso_girth - 1.0))
    parts += [
        Part("neck", "cone", v(0.0, 1.42, -0.025), np.r_[v(0.0, 1.58, -0.008), neck_r, neck_r]),
        Part("head", "ellipsoid", v(0.0, 1.655, 0.0), v(0.0775, 0.095, 0.0975)),
        Part("head", "ellipsoid", v(0.0, 1.585, 0.03), v(0.058, 0.07, 0.068)),
        Part("head", "ellipsoid", v(0.0, 1.62, 0.093), v(0.014, 0.028, 0.02)),
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


# ---------------------------------------------------------------------------- skinning
def _skin(layout: _Layout, verts: np.ndarray) -> np.ndarray:
    """Dense skin weights (V, B): softmax over bones of -sdf / tau at the rest vertices."""
    tau = SKIN_TAU * layout.scale
    dist = np.full((len(verts), len(BONE_NAMES)), np.inf)
    y = verts[:, 1]
    split_lo, split_hi = layout.torso_bands
    for part in layout.parts:
        d = part.sdf(verts)
        if isinstance(part, Torso):  # one loft, three bones: bands split at the spine pivots
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
_DEFAULT_SHAPE = BodyShape()


_ARRAYS = ("vertices", "triangles", "skin_indices", "skin_weights", "bone_parents", "bone_heads", "bind_matrices",
           "bone_joint", "bone_fraction", "point_bones", "point_rest")
"""The fields of a built-in body kept in the user's cache (the rest follow from the shape)."""
_BUILT_FROM = tuple(Path(__file__).parent / name for name in ("parametric.py", "parametric_sdf.py",
                                                             "parametric_shape.py", "landmarks.py", "skinned.py",
                                                             "skeleton.py"))
"""The code a cached body depends on: a change to any of it builds the body again."""
_BUILT_WITH = ("numpy", "scipy", "scikit-image", "open3d")
"""The libraries meshing and decimating it: another version of any builds the body again."""


@functools.lru_cache(maxsize=16)
def build_parametric_body(shape: BodyShape = _DEFAULT_SHAPE, resolution: float = 0.01) -> SkinnedBody:
    """The built-in skinned body for ``shape``, meshed on a grid of ``resolution`` metres.

    Returns a :class:`SkinnedBody` with about 12,000 triangles (fewer for coarse grids),
    19 bones (:data:`BONE_NAMES`), every named point of ``POINT_NAMES``, the pelvis at the
    origin. Deterministic and memoised on ``(shape, resolution)``: callers share the
    instance and must not modify its arrays in place (copy them first). Kept in the user's
    cache (:mod:`swarmpose.core.cache`), so that a later process loads it instead of meshing it.
    """
    if not 0.003 <= float(resolution) <= 0.03:
        raise ConfigError(f"body mesh resolution {resolution} m is outside the allowed range 0.003..0.03 m")
    key = cache_key(asdict(shape), float(resolution), [version(name) for name in _BUILT_WITH], sources=_BUILT_FROM)

    arrays = cached_arrays("bodies", key, lambda: _mesh_arrays(shape, float(resolution)))
    preset = preset_name(shape)
    return SkinnedBody(name="builtin" if preset in (None, "default") else f"builtin:{preset}",
                       bone_names=BONE_NAMES, point_names=POINT_NAMES,
                       metadata={"source": "builtin", "shape": asdict(shape), "resolution": float(resolution)},
                       **{name: np.array(arrays[name]) for name in _ARRAYS})


def _mesh_arrays(shape: BodyShape, resolution: float) -> dict[str, np.ndarray]:
    """The arrays (:data:`_ARRAYS`) of the built-in body of ``shape`` meshed anew (see
    :func:`build_parametric_body`)."""
    layout = _layout(shape)
    values, origin = sample_field(layout.parts, BLEND * layout.scale, float(resolution))
    verts, faces = mesh_field(values, origin, float(resolution), TARGET_TRIANGLES)
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
    return {"vertices": verts, "triangles": faces, "skin_indices": skin_indices, "skin_weights": skin_weights,
            "bone_parents": parents, "bone_heads": heads, "bind_matrices": body_frame_bind_matrices(heads),
            "bone_joint": bone_joint, "bone_fraction": np.array([f for *_, f in BONES], dtype=np.float64),
            "point_bones": np.array([BONE_INDEX[carriers[p]] for p in POINT_NAMES], dtype=np.int64),
            "point_rest": np.stack([exact[p] for p in POINT_NAMES]).astype(np.float64)}
