"""Open3D imported without its web viewer: ``import open3d`` also imports the Plotly/Dash viewer
(``open3d.visualization.draw_plotly``, 0.6-0.9 s of a 2-core machine's start-up, a third of the
library's import), which swarmpose never uses: it needs ray casting, point clouds and plane
fitting. :func:`open3d` puts a stand-in for that one module in place before the first import; its
functions import the real viewer when called, so ``open3d.visualization.draw_plotly(...)`` still
works for whoever calls it.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable

VIEWER = "open3d.visualization.draw_plotly"
"""The module whose import is put off until one of its functions is called."""
VIEWER_FUNCTIONS = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")
"""What ``open3d.visualization`` imports from it (Open3D 0.17-0.19)."""


def _real_viewer() -> types.ModuleType:
    """The real viewer module, imported now (the stand-in leaves ``sys.modules``)."""
    if getattr(sys.modules.get(VIEWER), "__swarmpose_stand_in__", False):
        del sys.modules[VIEWER]
    viewer = importlib.import_module(VIEWER)
    visualization = sys.modules["open3d.visualization"]
    for name in VIEWER_FUNCTIONS:  # later calls go straight to the real functions
        setattr(visualization, name, getattr(viewer, name))
    return viewer


def _deferred(name: str) -> Callable:
    def call(*args, **kwargs):
        return getattr(_real_viewer(), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = f"Open3D's ``visualization.{name}``, imported on first call."
    return call


def _stand_in() -> types.ModuleType:
    module = types.ModuleType(VIEWER, "Stand-in for Open3D's Plotly viewer, imported when a function is called.")
    module.__swarmpose_stand_in__ = True
    for name in VIEWER_FUNCTIONS:
        setattr(module, name, _deferred(name))
    return module


def open3d() -> types.ModuleType:
    """The ``open3d`` module, imported (once per process) without its Plotly/Dash viewer."""
    if "open3d" not in sys.modules and VIEWER not in sys.modules:
        sys.modules[VIEWER] = _stand_in()
    import open3d as o3d

    return o3d


__all__ = ["open3d"]
