"""Shape spaces: a body model as a function of a few numbers, for automatic personalisation.

A :class:`ShapeSpace` gives, for a parameter vector ``x`` (D,) within ``lower..upper``:

* :meth:`~ShapeSpace.full_body`: the full-resolution skinned body (for export);
* :meth:`~ShapeSpace.tracking_body`: its tracking level of detail with the *same topology
  for every x* (vertex and triangle counts, bones, skin), so an OpenCL scorer built once
  takes each new shape as a buffer upload (:meth:`ParticleScorer.set_body`), without a new
  program or a new decimation per candidate.

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

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError


class ShapeSpace(ABC):
    """A family of bodies indexed by ``x`` (D,) with named parameters (see the module docstring)."""

    kind: str = ""
    names: tuple[str, ...] = ()
    lower: np.ndarray
    upper: np.ndarray

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

    def clip(self, x) -> np.ndarray:
        """``x`` clipped to the space's bounds."""
        return np.clip(np.asarray(x, float), self.lower, self.upper)

    def parameters(self, x) -> dict[str, float]:
        """{name: value} of ``x``."""
        return {n: round(float(v), 4) for n, v in zip(self.names, self.clip(x))}


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
