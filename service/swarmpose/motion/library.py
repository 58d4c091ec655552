"""A motion by its spec: ``builtin:NAME`` (a procedural motion) or a BVH file retargeted onto a body."""

from __future__ import annotations

from pathlib import Path

from swarmpose.body.skinned import SkinnedBody
from swarmpose.motion.builtin import builtin_motion
from swarmpose.motion.retarget import load_motion
from swarmpose.motion.sequence import Motion


def load_motion_spec(spec: str, body: SkinnedBody, frames: int, fps: float) -> Motion:
    """``builtin:NAME`` -> ``frames`` frames of a procedural motion at ``fps``; anything else is a
    BVH file retargeted onto ``body`` and resampled to ``fps``."""
    if spec.startswith("builtin:"):
        return builtin_motion(spec.split(":", 1)[1], frames, fps)
    return load_motion(str(Path(spec).expanduser()), body, fps)
