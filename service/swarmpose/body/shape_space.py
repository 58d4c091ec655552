"""Shape spaces: a body model as a function of a few numbers, for automatic personalisation.

A :class:`ShapeSpace` gives, for a parameter vector ``x`` (D,) within ``lower..upper``:

* :meth:`~ShapeSpace.full_body`: the full-resolution skinned body (for export);
* :meth:`~ShapeSpace.tracking_body`: its tracking level of detail with the *same topology
  for every x* (vertex and triangle counts, bones, skin), so an OpenCL scorer built once
  takes each new shape as a buffer upload (:meth:`ParticleScorer.set_body`), without a new
  program or a new decimation per candidate;
* :meth:`~ShapeSpace.fitting_body`: the body a fit compares with the depth. A decimated mesh
  cuts the corners of the full one and encloses less (MakeHuman at 1,500 triangles: 2.3-2.4 %
  less volume, 0.4-0.6 cm less height, for every shape), so a fit that matched the tracking body
  to a person would make the full body that much too large. :class:`MakeHumanSpace` gives its
  tracking body moved out along its normals until it encloses the full body's volume
  (:func:`match_volume`).

Spaces: :class:`MakeHumanSpace` (the five macro sliders of
:mod:`swarmpose.body.makehuman_macros`) and, for the built-in body, whose marching-cubes mesh
changes topology with every shape, :class:`~swarmpose.body.builtin_shape_space.BuiltinSpace`
(stature and three girths; its tracking body deforms one decimated mesh analytically).
:func:`shape_space_for` picks one from a ``--body`` spec; a glTF file has no shape parameters
and is refused.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import replace
from functools import cached_property
from pathlib import Path

import numpy as np

from swarmpose.body.parametric_sdf import signed_volume, vertex_normals
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError


class ShapeSpace(ABC):
    """A family of bodies indexed by ``x`` (D,) with named parameters (see the module docstring)."""

    kind: str = ""
    names: tuple[str, ...] = ()
    lower: np.ndarray
    upper: np.ndarray
    own_pose_stage: bool = False
    """Whether a fit ends with the own-pose search (:mod:`~swarmpose.personalise.own_pose_search`): only
    where its steps, shares of each parameter's range, are tuned for this space."""

    def __init__(self, triangles: int = 1500):
        self.triangles = int(triangles)

    _start: np.ndarray
    """(D,) what :attr:`start` returns; each space sets it."""

    @property
    def start(self) -> np.ndarray:
        """(D,) the parameters a fit starts from (an average adult); a copy."""
        return self._start.copy()

    @abstractmethod
    def full_body(self, x) -> SkinnedBody:
        """The full-resolution body of parameters ``x`` (D,)."""

    @abstractmethod
    def tracking_body(self, x) -> SkinnedBody:
        """The tracking body of ``x``: same topology as :meth:`tracking_body` of any other x."""

    @abstractmethod
    def body_spec(self) -> str:
        """The ``--body`` spec of this space's bodies (``builtin`` or ``makehuman:DIR``)."""

    @abstractmethod
    def shape_spec(self, x) -> str:
        """The ``--shape`` text that gives the body of ``x`` again."""

    def fitting_body(self, x) -> SkinnedBody:
        """The body of ``x`` a shape fit scores (same topology for every x); here the tracking body,
        see the module docstring for the spaces that do better. A space whose full body's height
        differs from this body's puts it in the metadata as ``full_height_m``."""
        return self.tracking_body(x)

    def clip(self, x) -> np.ndarray:
        """``x`` clipped to the space's bounds."""
        return np.clip(np.asarray(x, float), self.lower, self.upper)

    def parameters(self, x) -> dict[str, float]:
        """{name: value} of ``x``."""
        return {n: round(float(v), 4) for n, v in zip(self.names, self.clip(x))}


def match_volume(lod: SkinnedBody, full: SkinnedBody, iterations: int = 3) -> SkinnedBody:
    """``lod`` with every vertex moved by one distance along its (area-weighted) normal so that
    it encloses the volume of ``full`` (both closed meshes in the rest pose, m): first order,
    dV = A·d with A the surface area, repeated ``iterations`` times. Bones, points and skin are
    unchanged; a negative distance shrinks."""
    tri = np.asarray(lod.triangles)
    verts = np.asarray(lod.vertices, np.float64)
    target = abs(signed_volume(np.asarray(full.vertices, np.float64), np.asarray(full.triangles)))
    outward = 1.0 if signed_volume(verts, tri) >= 0 else -1.0
    for _ in range(iterations):
        a, b, c = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
        area = 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
        normal = outward * vertex_normals(verts, tri)
        verts = verts + (target - abs(signed_volume(verts, tri))) / max(area, 1e-12) * normal
    return replace(lod, vertices=verts.astype(np.asarray(lod.vertices).dtype))


class NearestVertexLod:
    """A tracking LOD whose vertices follow a full mesh of fixed topology: each LOD vertex
    moves with the full mesh's vertex nearest to it in the reference shape (the decimation's
    own skin-weight rule, :meth:`SkinnedBody.tracking_lod`)."""

    def __init__(self, reference: SkinnedBody, triangles: int):
        from scipy.spatial import cKDTree

        self.reference = reference
        self.lod = reference.tracking_lod(triangles)
        self.nearest = cKDTree(reference.vertices).query(self.lod.vertices)[1]

    def follow(self, full: SkinnedBody) -> SkinnedBody:
        """The LOD of ``full`` (same topology as the reference's full mesh)."""
        if len(full.vertices) != len(self.reference.vertices):
            raise ConfigError(f"{full.name}: {len(full.vertices)} vertices, the reference shape has "
                              f"{len(self.reference.vertices)}; a shape space keeps the mesh's topology")
        moved = self.lod.vertices + (full.vertices - self.reference.vertices)[self.nearest]
        return replace(self.lod, name=f"{full.name}@{len(self.lod.triangles)}", vertices=moved,
                       bone_heads=full.bone_heads, bind_matrices=full.bind_matrices, point_rest=full.point_rest,
                       metadata={**full.metadata, "lod_triangles": int(len(self.lod.triangles))})


class MakeHumanSpace(ShapeSpace):
    """The MakeHuman body over its macro sliders (gender, caucasian, muscle, weight, height)."""

    kind = "makehuman"
    own_pose_stage = True  # its own-pose steps are tuned for these macro sliders

    def __init__(self, directory: str | Path, triangles: int = 1500):
        from swarmpose.body.makehuman_macros import MACRO_NAMES, MacroShape

        super().__init__(triangles)
        self.directory = str(Path(directory).expanduser())
        self.names = MACRO_NAMES
        self.lower, self.upper = np.zeros(len(MACRO_NAMES)), np.ones(len(MACRO_NAMES))
        self._start = MacroShape().vector()

    def macros(self, x):
        from swarmpose.body.makehuman_macros import MacroShape

        return MacroShape.from_vector(self.clip(x))

    def full_body(self, x) -> SkinnedBody:
        from swarmpose.body.makehuman import makehuman_body

        shape = self.macros(x)
        return makehuman_body(self.directory, shape.recipe(), f"makehuman:{self.shape_spec(x)}",
                              {"macros": shape.as_dict()})

    @cached_property
    def _lod(self) -> NearestVertexLod:
        return NearestVertexLod(self.full_body(self.start), self.triangles)

    def tracking_body(self, x) -> SkinnedBody:
        return self._lod.follow(self.full_body(x))

    def fitting_body(self, x) -> SkinnedBody:
        """The tracking body of ``x`` enclosing the full body's volume (:func:`match_volume`); its
        metadata's ``full_height_m`` is the full body's rest height (the tracking mesh's is 2-5 mm
        less)."""
        full = self.full_body(x)
        body = match_volume(self._lod.follow(full), full)
        return replace(body, metadata={**body.metadata, "full_height_m": full.height})

    def body_spec(self) -> str:
        return f"makehuman:{self.directory}"

    def shape_spec(self, x) -> str:
        return ",".join(f"{k}={v:.3f}" for k, v in self.macros(x).as_dict().items())


def shape_space_for(body: str, shape: str = "", triangles: int = 1500) -> ShapeSpace:
    """The shape space of ``--body`` ``body`` (``shape``: the built-in body's sex is kept from it).

    A ``.glb`` / ``.gltf`` body is already fixed: ConfigError naming what to pass instead."""
    if body.startswith("makehuman:"):
        return MakeHumanSpace(body.split(":", 1)[1], triangles)
    if body == "builtin":
        from swarmpose.body.builtin_shape_space import BuiltinSpace

        return BuiltinSpace(shape, triangles)
    if body.lower().endswith((".glb", ".gltf")):
        raise ConfigError(f"{body} is a fixed body with no shape parameters to fit; personalise from "
                          "--body makehuman:DIR (the MakeHuman assets) or --body builtin, and load the result "
                          "with --body ME.glb")
    raise ConfigError(f"unknown body {body!r}; personalisation takes --body makehuman:DIR or --body builtin")
