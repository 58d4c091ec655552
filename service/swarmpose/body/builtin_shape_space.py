"""The shape space of the built-in parametric body: stature and three girths, one topology.

Parameters ``x`` (4,) = (``height``, ``torso``, ``arms``, ``legs``):

* ``height``: a 0..1 *slider* mapped linearly onto the statures :data:`STATURE_RANGE`
  (1.45..2.05 m; 0.5 = 1.75 m), so that the fitter's sweep grid, which gives values in 0..1
  by parameter name, means the same here as for MakeHuman's height slider.
  :meth:`BuiltinSpace.parameters` shows the slider; :meth:`BuiltinSpace.shape_spec` writes the
  stature in metres (``height=1.812,torso=1.050,arms=0.970,legs=1.010,sex=neutral``);
* ``torso`` / ``arms`` / ``legs``: the girth factors of :class:`BodyShape`, within
  :data:`GIRTH_BOUNDS` (0.7..1.5).

The sex is not a parameter: it is kept from the ``--shape`` spec the space is made with.

:meth:`BuiltinSpace.full_body` is the exact body (:func:`build_parametric_body`: a signed-distance
field meshed by marching cubes, whose topology changes with every shape).
:meth:`BuiltinSpace.tracking_body` has one topology for every x: the start shape's body is
decimated once and its vertices follow the shape analytically (well under a millisecond):

* **girth**: the body is a smooth union of primitives (tapered capsules, ellipsoids, a rounded
  box, a lofted torso; :mod:`swarmpose.body.parametric_sdf`) whose radii, and whose shoulder
  joints, are linear in the girth factors (the torso girth also widens the shoulders, and the
  neck by half as much; the feet and head do not change). Each primitive has an exact map of
  its surface onto its surface at other girths: radial scaling about a capsule's axis,
  per-axis scaling of an ellipsoid, scaling of a rounded box's core, horizontal scaling of a
  torso section about its centre line, plus the primitive's translation when the shoulders
  move. A vertex takes the maps of the primitives it lies on, weighted by a softmax of their
  signed distances at the start shape (:data:`PRIMITIVE_TAU`), which also carries the smooth
  union's seams. These maps are linear in the girths. Where a primitive grows over a vertex
  that lay on another (a wide torso swallowing the top of the thigh), the vertex is pushed out
  by one Newton step on that primitive's distance (linearised in the girths), so the hips and
  armpits do not fold inwards;
* **height**: every length and radius of the built-in body (and the smooth-union blend
  radius) is proportional to stature and the pelvis is the origin, so stature is a uniform
  scale about the origin of vertices, bone heads, bind matrices and named points.

Bone heads follow the construction (the arm bones move out with the torso girth) and each
named point moves with its carrier bone's head. Limits, measured against the exact body with
:func:`tests.conftest.surface_distance`: mean distance below 2.5 mm over the whole box, and
a few vertices where primitives merge (the crotch at thick legs, the armpit) end up to
several cm inside the exact surface, hidden from the camera.
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
"""Statures (m) that the ``height`` slider's 0 and 1 stand for."""
GIRTH_BOUNDS = (0.7, 1.5)
"""Bounds of the three girth factors (unitless)."""
START_STATURE = 1.75
"""Stature (m) of the start shape (slider 0.5); its girths are 1."""
PRIMITIVE_TAU = 0.004
"""Softmax temperature (m of signed distance) of a vertex's weights over the primitives it lies on."""
MIN_PRIMITIVE_WEIGHT = 1e-3
"""Primitive weights below this are dropped (and the rest renormalised)."""
SWALLOW_WINDOW = 0.08
"""Primitives farther than this (m, at the start shape) from a vertex are not checked for growing over it."""
GIRTHS = ("torso_girth", "arm_girth", "leg_girth")
"""The :class:`BodyShape` fields of parameters 1..3, in order."""
_GIRTH_STEP = 0.5
"""Girth change over which each direction of the linear model is read."""
_GRADIENT_STEP = 1e-5
"""Central-difference step (m) of the primitives' distance gradients."""


def stature_of(slider: float) -> float:
    """Stature (m) of ``height`` slider value ``slider`` (0..1, clipped)."""
    lo, hi = STATURE_RANGE
    return lo + (hi - lo) * float(np.clip(slider, 0.0, 1.0))


def slider_of(stature: float) -> float:
    """``height`` slider value (0..1) of stature ``stature`` m; ConfigError outside :data:`STATURE_RANGE`."""
    lo, hi = STATURE_RANGE
    if not lo <= float(stature) <= hi:
        raise ConfigError(f"stature {stature} m is outside the built-in shape space's range {lo}..{hi} m")
    return (float(stature) - lo) / (hi - lo)


# ---------------------------------------------------------------------------- primitive maps
def _map_part(ref: Part | Torso, new: Part | Torso, p: np.ndarray) -> np.ndarray:
    """Points ``p`` (N, 3) m on or near primitive ``ref``, carried to the same place on ``new`` (N, 3) m.

    ``ref`` and ``new`` are one primitive at two girths (same kind and frame)."""
    if isinstance(ref, Torso):  # elliptical sections scaled about their centre line x = 0, z = c(y)
        a0, b0, c0 = ref.profile(p[:, 1])
        a1, b1, c1 = new.profile(p[:, 1])
        return np.stack([p[:, 0] * a1 / a0, p[:, 1], c1 + (p[:, 2] - c0) * b1 / b0], axis=1)
    if ref.kind == "cone":  # offset from the axis scaled by the ratio of the radii at that axis position
        axis0, axis1 = ref.size[:3] - ref.centre, new.size[:3] - new.centre
        t = np.clip((p - ref.centre) @ axis0 / (axis0 @ axis0), 0.0, 1.0)
        r0 = ref.size[3] + (ref.size[4] - ref.size[3]) * t
        r1 = new.size[3] + (new.size[4] - new.size[3]) * t
        return new.centre + t[:, None] * axis1 + (p - ref.centre - t[:, None] * axis0) * (r1 / r0)[:, None]
    frame = np.eye(3) if ref.frame is None else ref.frame
    q = (p - ref.centre) @ frame.T
    if ref.kind == "ellipsoid":
        q = q * (new.size / ref.size)
    elif ref.kind == "box":  # the core box scales, the rounding shell keeps its thickness
        core0, core1 = ref.size - ref.rounding, new.size - new.rounding
        inside = np.clip(q, -core0, core0)
        q = inside * (core1 / core0) + (q - inside)
    else:
        raise ValueError(f"unknown primitive kind {ref.kind!r}")
    return new.centre + q @ frame


def _newton_step(part: Part | Torso, p: np.ndarray) -> np.ndarray:
    """(N, 3) m per m of distance: ``grad / |grad|^2`` of the part's distance at points ``p`` (N, 3) m,
    so that ``p - d * step`` is one Newton step from distance ``d`` to the part's surface."""
    h = _GRADIENT_STEP
    grad = np.stack([(part.sdf(p + e) - part.sdf(p - e)) / (2.0 * h) for e in np.eye(3) * h], axis=1)
    return grad / np.maximum(np.sum(grad * grad, axis=1, keepdims=True), 1e-12)


@dataclass(frozen=True)
class _GirthModel:
    """The start body's tracking LOD and how it follows the girths, all at the start stature.

    ``G`` = 3 girths (:data:`GIRTHS`), ``V`` vertices, ``B`` bones, ``N`` named points, ``M``
    (vertex, primitive) pairs where the primitive may grow over the vertex.

    lod: the decimated start body, pelvis at the origin, m.
    vertices / heads / points: (G, V, 3) / (G, B, 3) / (G, N, 3) m of displacement per unit of
    each girth factor under the primitives' maps.
    swallow_vertex: (M,) the pair's vertex; swallow_sdf: (M,) m the primitive's signed distance
    there at the start shape (>= 0); swallow_dirs: (G, M) m its change per unit girth at the
    mapped vertex; swallow_step: (M, 3) the primitive's Newton step per m of distance.
    """

    lod: SkinnedBody
    vertices: np.ndarray
    heads: np.ndarray
    points: np.ndarray
    swallow_vertex: np.ndarray
    swallow_sdf: np.ndarray
    swallow_dirs: np.ndarray
    swallow_step: np.ndarray

    def deform(self, g: np.ndarray) -> np.ndarray:
        """(V, 3) m vertices for girth changes ``g`` (G,) (factor minus 1), at the start stature."""
        v = self.lod.vertices + np.tensordot(g, self.vertices, 1)
        depth = -(self.swallow_sdf + g @ self.swallow_dirs)  # > 0: the primitive has grown over the vertex
        inside = depth > 0.0
        if np.any(inside):
            push = np.zeros_like(v)
            np.add.at(push, self.swallow_vertex[inside], depth[inside, None] * self.swallow_step[inside])
            v = v + push
        return v


def _primitive_weights(parts: tuple, p: np.ndarray) -> np.ndarray:
    """(P, N) weights of the primitives ``parts`` at points ``p`` (N, 3) m: a softmax of -sdf / tau."""
    d = np.stack([part.sdf(p) for part in parts])
    w = np.exp(-(d - d.min(axis=0)) / PRIMITIVE_TAU)
    w[w < MIN_PRIMITIVE_WEIGHT] = 0.0
    return w / w.sum(axis=0)


def _girth_model(sex: str, triangles: int) -> _GirthModel:
    """Decimate the start body of ``sex`` to about ``triangles`` triangles and read its girth model.

    The primitives are those of the construction (:func:`swarmpose.body.parametric._layout`) at
    the reference stature, in its own frame (soles at y = 0)."""
    start = BodyShape(height=START_STATURE, sex=sex)
    lod = build_parametric_body(start).tracking_lod(triangles)
    ref = _layout(replace(start, height=REFERENCE_HEIGHT))
    root = ref.heads[0]
    p = lod.vertices * (REFERENCE_HEIGHT / START_STATURE) + root
    weights = _primitive_weights(ref.parts, p)  # (P, V)
    sdf = np.stack([part.sdf(p) for part in ref.parts])
    part_of, vertex_of = np.nonzero((sdf < SWALLOW_WINDOW) & (weights < 0.5))  # candidates to grow over a vertex
    swallow_sdf = np.maximum(sdf[part_of, vertex_of], 0.0)
    step = np.zeros((len(part_of), 3))
    vertex_dirs, head_dirs, swallow_dirs = [], [], []
    for k, part in enumerate(ref.parts):
        sel = part_of == k
        if np.any(sel):
            step[sel] = _newton_step(part, p[vertex_of[sel]])
    for name in GIRTHS:
        new = _layout(replace(start, height=REFERENCE_HEIGHT, **{name: 1.0 + _GIRTH_STEP}))
        if len(new.parts) != len(ref.parts) or not np.allclose(new.heads[0], root):
            raise ConfigError("the built-in body's construction changed (its primitives or its pelvis move with "
                              "the girth); the built-in shape space cannot follow it")
        moved = np.zeros_like(p)
        for part0, part1, w in zip(ref.parts, new.parts, weights, strict=True):
            used = w > 0.0
            if np.any(used):
                moved[used] += w[used, None] * _map_part(part0, part1, p[used])
        new_sdf = np.zeros(len(part_of))
        for k, part in enumerate(new.parts):
            sel = part_of == k
            if np.any(sel):
                new_sdf[sel] = part.sdf(moved[vertex_of[sel]])
        vertex_dirs.append((moved - p) / _GIRTH_STEP)
        head_dirs.append((new.heads - ref.heads) / _GIRTH_STEP)
        swallow_dirs.append((new_sdf - swallow_sdf) / _GIRTH_STEP)
    scale = START_STATURE / REFERENCE_HEIGHT  # read at the reference stature, used at the start stature
    heads = np.stack(head_dirs) * scale
    return _GirthModel(lod=lod, vertices=np.stack(vertex_dirs) * scale, heads=heads,
                       points=heads[:, lod.point_bones],  # a named point moves with its carrier bone's head
                       swallow_vertex=vertex_of, swallow_sdf=swallow_sdf * scale,
                       swallow_dirs=np.stack(swallow_dirs) * scale, swallow_step=step)


# ---------------------------------------------------------------------------- the space
class BuiltinSpace(ShapeSpace):
    """The built-in body over (height slider, torso, arms, legs); see the module docstring.

    ``shape``: a ``--shape`` spec (preset and/or ``key=value``; empty = the default body) whose
    sex the space keeps; its stature and girths are not used (a fit starts at :attr:`start`).
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

    def _values(self, x) -> tuple[float, np.ndarray]:
        """Stature (m) and girth factors (3,) of ``x`` (4,), clipped to the bounds."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (len(self.names),) or not np.all(np.isfinite(x)):
            raise ConfigError(f"built-in shape parameters must be {len(self.names)} finite numbers "
                              f"({', '.join(self.names)}), got {x.tolist()}")
        x = self.clip(x)
        return stature_of(x[0]), x[1:]

    def body_shape(self, x) -> BodyShape:
        """The :class:`BodyShape` of ``x`` (4,), clipped, with the stature (m) and girths rounded to
        3 decimals as :meth:`shape_spec` writes them."""
        stature, girths = self._values(x)
        return BodyShape(round(stature, 3), *(round(float(g), 3) for g in girths), sex=self.sex)

    def full_body(self, x) -> SkinnedBody:
        """The exact built-in body of ``x`` (4,): about 12,000 triangles, topology varying with x (the
        body :func:`~swarmpose.body.loader.load_body` gives for :meth:`shape_spec`)."""
        return build_parametric_body(self.body_shape(x))

    @cached_property
    def _model(self) -> _GirthModel:
        return _girth_model(self.sex, self.triangles)

    def tracking_body(self, x) -> SkinnedBody:
        """The tracking body of ``x`` (4,): the start body's LOD, deformed; the same topology for every x.

        The first call builds and decimates the start body (seconds); later calls take well under 1 ms."""
        stature, girths = self._values(x)
        model = self._model
        lod = model.lod
        g = girths - 1.0
        s = stature / START_STATURE
        heads = (lod.bone_heads + np.tensordot(g, model.heads, 1)) * s
        return replace(lod, name=f"builtin:{self.shape_spec(x)}@{len(lod.triangles)}",
                       vertices=model.deform(g) * s, bone_heads=heads, bind_matrices=body_frame_bind_matrices(heads),
                       point_rest=(lod.point_rest + np.tensordot(g, model.points, 1)) * s,
                       metadata={**lod.metadata, "shape": asdict(self.body_shape(x)), "full_height_m": float(stature)})

    def body_spec(self) -> str:
        return "builtin"

    def shape_spec(self, x) -> str:
        """``height=H,torso=T,arms=A,legs=L,sex=S`` for ``x`` (4,), with the stature H in metres."""
        b = self.body_shape(x)
        return (f"height={b.height:.3f},torso={b.torso_girth:.3f},arms={b.arm_girth:.3f},"
                f"legs={b.leg_girth:.3f},sex={b.sex}")
