"""Resolve a ``--body`` / ``--shape`` pair to a :class:`SkinnedBody`.

``BODY`` is ``builtin`` (the parametric body; ``--shape`` a preset or ``height=..,torso=..``),
``makehuman:DIR`` (the MakeHuman assets directory; ``--shape`` a MakeHuman preset, or macro
sliders ``gender=0.3,weight=0.8,...`` after an optional preset, see
:mod:`swarmpose.body.makehuman_macros`) or a
``.glb`` / ``.gltf`` file (``--shape`` ignored: the file is already personalised).

Imports inside the functions are deliberate: each body module is imported when its spec is
used, so the built-in body never reads MakeHuman or glTF code.
"""

from __future__ import annotations

from pathlib import Path

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError

DEFAULT_SHAPE = {"builtin": "default", "makehuman": "male"}


def load_body(body: str, shape: str | None = None) -> SkinnedBody:
    """The body named by ``body`` in shape ``shape`` (None = that body's default)."""
    if body == "builtin":
        from swarmpose.body.parametric import build_parametric_body
        from swarmpose.body.parametric_shape import parse_shape
        return build_parametric_body(parse_shape(shape or DEFAULT_SHAPE["builtin"]))
    if body.startswith("makehuman:"):
        directory = str(Path(body.split(":", 1)[1]).expanduser())
        if shape and "=" in shape:  # macro sliders, optionally after a preset: a personalised shape
            from swarmpose.body.makehuman_macros import parse_macros
            from swarmpose.body.shape_space import MakeHumanSpace
            return MakeHumanSpace(directory).full_body(parse_macros(shape).vector())
        from swarmpose.body.makehuman import load_makehuman
        return load_makehuman(directory, shape or DEFAULT_SHAPE["makehuman"])
    if body.lower().endswith((".glb", ".gltf")):
        from swarmpose.body.gltf_read import load_glb
        return load_glb(Path(body).expanduser())
    raise ConfigError(f"unknown body {body!r}; use 'builtin', 'makehuman:DIR' (the MakeHuman assets "
                      "directory) or a .glb/.gltf file")
