"""swarmpose: markerless 3D human pose tracking for RGBD cameras.

A personalised skinned body model is fitted to each depth frame by particle swarm
optimisation of an objective that combines the rendered-vs-observed depth discrepancy
with the distance to 2D joints found by a neural detector.

The public API (imported on first use, so ``import swarmpose`` stays light):

* :class:`Tracker` — track frames from your own code; :func:`track` — any source URI;
* :class:`Intrinsics` — the pinhole camera; :class:`FrameResult`, :class:`BodyResult`,
  :class:`Joint` — what tracking gives (``to_message()``: the protocol's frame message);
* :func:`open_source` — frames from folders, recordings and cameras; :func:`load_body` —
  a body model; :class:`TrackerConfig` — every tracker setting;
* :class:`SwarmposeError` — the base of every error swarmpose raises on purpose.

The library logs to the ``swarmpose`` logger and adds no handler of its own.
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "Tracker": "swarmpose.pipeline.api", "track": "swarmpose.pipeline.api",
    "Intrinsics": "swarmpose.core.camera", "SwarmposeError": "swarmpose.core.errors",
    "FrameResult": "swarmpose.tracking.result", "BodyResult": "swarmpose.tracking.result",
    "Joint": "swarmpose.tracking.result", "TrackerConfig": "swarmpose.tracking.config",
    "Frame": "swarmpose.sources.base", "open_source": "swarmpose.sources.registry",
    "load_body": "swarmpose.body.loader",
}
__all__ = sorted([*_EXPORTS, "__version__"])

logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'swarmpose' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
