"""The shape space of the built-in parametric body: stature and three girths, one topology.

Parameters ``x`` (4,) = (``height``, ``torso``, ``arms``, ``legs``):

* ``height``: a 0..1 *slider* mapped linearly onto statures :data:`STATURE_RANGE`
  (1.45..2.05 m; 0.5 = 1.75 m), so that the fitter's sweep grid, which gives values in 0..1
  by parameter name, means the same here as for MakeHuman's height slider;
* ``torso`` / ``arms`` / ``legs``: the girth factors of :class:`BodyShape` within
  :data:`GIRTH_BOUNDS` (0.7..1.5).

The sex is not a parameter: it is kept from the ``--shape`` spec the space is made with.

:meth:`BuiltinSpace.full_body` is the exact body (:func:`build_parametric_body`: an SDF
meshed by marching cubes, whose topology changes with every shape). :meth:`BuiltinSpace.tracking_body`
is a level of detail of *fixed* topology: the start shape's body is decimated once, and
its vertices follow the shape analytically, as a linear blend shape:

* girth: the body is a smooth union of primitives (cones, ellipsoids, a rounded box, a
  lofted torso) whose radii, and whose shoulder joints, are linear in the girth factors.
  Each primitive has an exact map of its own surface onto its surface at other girths
  (radial scaling about a cone's axis, per-axis scaling of an ellipsoid, scaling of a
  rounded box's core, horizontal scaling of the torso loft about its centre line, plus the
  primitive's own translation when the shoulders move). A vertex takes the maps of the
  primitives it lies on, weighted by a softmax of their signed distances at the start shape
  (:data:`PRIMITIVE_TAU`), which also blends them across the smooth-union seams. Every map
  is linear in the girths, so this is ``vertices = base + sum_i (g_i - 1) * direction_i``;
  bone heads (the arm bones move out with the torso's girth) and named points (each moves
  with its carrier bone's head) are linear alike;
* height: every length and radius of the built-in body (and its smooth-union blend radius)
  is proportional to stature and the pelvis is the origin, so a stature change is a uniform
  scale about the origin of vertices, bone heads, bind matrices and named points.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import cached_property

import numpy as np

from swarmpose.body.parametric import REFERENCE_HEIGHT, _layout, build_parametric_body
from swarmpose.body.parametric_sdf import Part, Torso
from swarmpose.body.parametric_shape import BodyShape, parse_shape
from swarmpose.body.shape_space import ShapeSpace
from swarmpose.body.skinned import SkinnedBody, body_frame_bind_matrices
from swarmpose.core.errors import ConfigError

STATURE_RANGE = (1.45, 2.05)
"""Statures (m) the ``height`` slider's 0 and 1 stand for."""
GIRTH_BOUNDS = (0.7, 1.5)
"""Bounds of the three girth factors (unitless)."""
START_STATURE = 1.75
"""Stature (m) of the start shape (slider 0.5); its girths are 1."""
PRIMITIVE_TAU = 0.004
"""Softmax temperature (m of signed distance) of a vertex's weights over the primitives it lies on."""
MIN_PRIMITIVE_WEIGHT = 1e-3
"""Primitive weights below this are dropped (and the rest renormalised)."""
PUSH_WINDOW = 0.08
MODE = "sum"
_GIRTH_STEP = 0.5
"""Girth change used to read each linear map's direction (any step gives the same, the maps being linear)."""


def stature_of(slider: float) -> float:
    """Stature (m) of ``height`` slider value ``slider`` (0..1, clipped)."""
    lo, hi = STATURE_RANGE
    return lo + (hi - lo) * float(np.clip(slider, 0.0, 1.0))


def slider_of(stature: float) -> float:
    """``height`` slider value (0..1) of stature ``stature`` (m); ConfigError outside :data:`STATURE_RANGE`."""
    lo, hi = STATURE_RANGE
    if not lo <= float(stature) <= hi:
        raise ConfigError(f"stature {stature} m is outside the built-in shape space's range {lo}..{hi} m")
    return (float(stature) - lo) / (hi - lo)


# ---------------------------------------------------------------------------- primitive maps
def _map_part(ref: Part | Torso, new: Part | Torso, p: np.ndarray) -> np.ndarray:
    """Points (N, 3) m on or near primitive ``ref`` carried to the same place on ``new`` (N, 3) m.

    ``ref`` and ``new`` are one primitive at two girths (same kind, same frame)."""
    if isinstance(ref, Torso):  # elliptical sections scaled about their centre line (x = 0, z = c(y))
        a0, b0, c0 = ref.profile(p[:, 1])
        a1, b1, c1 = new.profile(p[:, 1])
        return np.stack([p[:, 0] * a1 / a0, p[:, 1], c1 + (p[:, 2] - c0) * b1 / b0], axis=1)
    if ref.kind == "cone":  # radial offset from the axis scaled by the ratio of radii at that axis position
        axis0, axis1 = ref.size[:3] - ref.centre, new.size[:3] - new.centre
        t = np.clip((p - ref.centre) @ axis0 / (axis0 @ axis0), 0.0, 1.0)
        foot0 = ref.centre + t[:, None] * axis0
        r0 = ref.size[3] + (ref.size[4] - ref.size[3]) * t
        r1 = new.size[3] + (new.size[4] - new.size[3]) * t
        return new.centre + t[:, None] * axis1 + (p - foot0) * (r1 / r0)[:, None]
    frame = np.eye(3) if ref.frame is None else ref.frame
    q = (p - ref.centre) @ frame.T
    if ref.kind == "ellipsoid":
        q = q * (new.size / ref.size)
    elif ref.kind == "box":  # scale the core box; the rounding shell keeps its thickness
        core0, core1 = ref.size - ref.rounding, new.size - new.rounding
        inside = np.clip(q, -core0, core0)
        q = inside * (core1 / core0) + (q - inside)
    else:
        raise ValueError(ref.kind)
    return new.centre + q @ frame


@dataclass(frozen=True)
class _BlendShape:
    """doc"""

    lod: SkinnedBody
    vertices: np.ndarray
    heads: np.ndarray
    points: np.ndarray
    push_index: np.ndarray  # (M,) vertex of each (vertex, primitive) pair that may swallow it
    push_sdf: np.ndarray  # (M,) sdf of the primitive at the vertex at start
    push_dirs: np.ndarray  # (G, M) change of it per unit girth
    push_normal: np.ndarray  # (M, 3)

    def deform(self, g):
        v = self.lod.vertices + np.tensordot(g, self.vertices, 1)
        depth = -(self.push_sdf + g @ self.push_dirs)
        inside = depth > 0
        if np.any(inside):
            idx = self.push_index[inside]
            push = depth[inside, None] * self.push_normal[inside]
            out = np.zeros_like(v)
            np.add.at(out, idx, push)
            if MODE == "max":
                best = np.zeros(len(v))
                np.maximum.at(best, idx, depth[inside])
                keep = depth[inside] >= best[idx]
                out = np.zeros_like(v)
                out[idx[keep]] = push[keep]
            v = v + out
        return v


def _primitive_weights(parts: tuple, p: np.ndarray) -> np.ndarray:
    d = np.stack([part.sdf(p) for part in parts])
    w = np.exp(-(d - d.min(axis=0)) / PRIMITIVE_TAU)
    w[w < MIN_PRIMITIVE_WEIGHT] = 0.0
    return w / w.sum(axis=0)


def _sdf_and_normal(part, p, h=1e-5):
    d = part.sdf(p)
    n = np.stack([(part.sdf(p + e) - part.sdf(p - e)) / (2 * h) for e in np.eye(3) * h], axis=1)
    return d, n / np.maximum(np.sum(n * n, axis=1, keepdims=True), 1e-12)


def _blend_shape(sex: str, triangles: int) -> _BlendShape:
    """Decimate the start body and read the girth directions of its vertices, bones and points."""
    start = BodyShape(height=START_STATURE, sex=sex)
    lod = build_parametric_body(start).tracking_lod(triangles)
    ref = _layout(replace(start, height=REFERENCE_HEIGHT))  # the construction's own frame: soles at y = 0
    root = ref.heads[0]
    p = lod.vertices * (REFERENCE_HEIGHT / START_STATURE) + root
    weights = _primitive_weights(ref.parts, p)
    d0 = np.stack([part.sdf(p) for part in ref.parts])  # (P, V)
    near = (d0 < PUSH_WINDOW) & (weights < 0.5)
    pk, pv = np.nonzero(near)
    vertex_dirs, head_dirs, push_dirs = [], [], []
    layouts = []
    for field in ("torso_girth", "arm_girth", "leg_girth"):
        new = _layout(replace(start, height=REFERENCE_HEIGHT, **{field: 1.0 + _GIRTH_STEP}))
        if len(new.parts) != len(ref.parts) or not np.allclose(new.heads[0], root):
            raise ConfigError("the built-in body's construction changed: its primitives or its pelvis moved with "
                              "the girth, which the built-in shape space cannot follow")
        moved = np.zeros_like(p)
        for part0, part1, w in zip(ref.parts, new.parts, weights, strict=True):
            used = w > 0
            if np.any(used):
                moved[used] += w[used, None] * _map_part(part0, part1, p[used])
        vertex_dirs.append((moved - p) / _GIRTH_STEP)
        head_dirs.append((new.heads - ref.heads) / _GIRTH_STEP)
        layouts.append((new, moved))
    push_sdf = d0[pk, pv]
    normals = np.zeros((len(pk), 3))
    for k, part in enumerate(ref.parts):
        sel = pk == k
        if np.any(sel):
            normals[sel] = _sdf_and_normal(part, p[pv[sel]])[1]
    for new, _ in layouts:
        d1 = np.zeros(len(pk))
        # q0 at this girth step: all three maps combined? only this one changes
        for k, part in enumerate(new.parts):
            sel = pk == k
            if np.any(sel):
                d1[sel] = part.sdf(_[pv[sel]])
        push_dirs.append((d1 - push_sdf) / _GIRTH_STEP)
    scale = START_STATURE / REFERENCE_HEIGHT  # directions were read at the reference stature
    vertices, heads = np.stack(vertex_dirs) * scale, np.stack(head_dirs) * scale
    points = heads[:, lod.point_bones]  # a named point moves with its carrier bone's head
    return _BlendShape(lod, vertices, heads, points, pv, push_sdf * scale, np.stack(push_dirs) * scale, normals)


# ---------------------------------------------------------------------------- the space
class BuiltinSpace(ShapeSpace):
    """The built-in body over (height slider, torso, arms, legs) (see the module docstring).

    ``shape``: a ``--shape`` spec (preset and/or ``key=value``; empty = default) whose sex
    the space keeps; its stature and girths are not used (a fit starts at :attr:`start`).
    ``triangles``: the tracking level of detail's triangle count.
    """

    kind = "builtin"
    names = ("height", "torso", "arms", "legs")

    def __init__(self, shape: str = "", triangles: int = 1500):
        super().__init__(triangles)
        self.sex = parse_shape(shape or "").sex
        lo, hi = GIRTH_BOUNDS
        self.lower = np.array([0.0, lo, lo, lo])
        self.upper = np.array([1.0, hi, hi, hi])
        self._start = np.array([slider_of(START_STATURE), 1.0, 1.0, 1.0])

    @property
    def start(self) -> np.ndarray:
        return self._start.copy()

    def body_shape(self, x) -> BodyShape:
        """The :class:`BodyShape` of ``x`` (4,), clipped and rounded as :meth:`shape_spec` writes it
        (stature and girths to 3 decimals: 1 mm, 0.1 %)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (len(self.names),) or not np.all(np.isfinite(x)):
            raise ConfigError(f"built-in shape parameters must be {len(self.names)} finite numbers "
                              f"({', '.join(self.names)}), got {x!r}")
        x = self.clip(x)
        return BodyShape(height=round(stature_of(x[0]), 3), torso_girth=round(float(x[1]), 3),
                         arm_girth=round(float(x[2]), 3), leg_girth=round(float(x[3]), 3), sex=self.sex)

    def full_body(self, x) -> SkinnedBody:
        """The exact built-in body of ``x`` (4,) (about 12,000 triangles; topology varies with x)."""
        return build_parametric_body(self.body_shape(x))

    @cached_property
    def _blend(self) -> _BlendShape:
        return _blend_shape(self.sex, self.triangles)

    def tracking_body(self, x) -> SkinnedBody:
        """The tracking LOD of ``x`` (4,): the start body's LOD deformed (one topology for every x)."""
        shape = self.body_shape(x)
        blend = self._blend
        lod = blend.lod
        g = np.array([shape.torso_girth, shape.arm_girth, shape.leg_girth]) - 1.0
        s = shape.height / START_STATURE
        heads = (lod.bone_heads + np.tensordot(g, blend.heads, 1)) * s
        return replace(lod, name=f"builtin:{self.shape_spec(x)}@{len(lod.triangles)}",
                       vertices=blend.deform(g) * s,
                       bone_heads=heads, bind_matrices=body_frame_bind_matrices(heads),
                       point_rest=(lod.point_rest + np.tensordot(g, blend.points, 1)) * s,
                       metadata={**lod.metadata, "shape": asdict(shape)})

    def body_spec(self) -> str:
        return "builtin"

    def shape_spec(self, x) -> str:
        """``height=H,torso=T,arms=A,legs=L,sex=S`` with the real stature H in metres."""
        b = self.body_shape(x)
        return (f"height={b.height:.3f},torso={b.torso_girth:.3f},arms={b.arm_girth:.3f},"
                f"legs={b.leg_girth:.3f},sex={b.sex}")
