"""``Motion``: a body-independent sequence of tracking-skeleton poses in a world frame.

World frame: X = the subject's left at the first frame, Y = up, Z = forward, metres, the
floor at y = 0. A motion does not know the body it will drive: joint angles mean the same
on every body (zero = T-pose) and the root position is an offset from where the root of
*any* body stands in its rest pose above the world origin; ``swarmpose synth`` then moves
the whole sequence up or down so the lowest sole touches the floor. Retargeted BVH
clips and the built-in procedural motions both produce it; ``swarmpose synth`` places
a camera and turns it into camera-frame 36-D poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.body.skeleton import ANGLE_LIMITS, N_ANGLES
from swarmpose.core.errors import ShapeError, check_shape


@dataclass(frozen=True)
class Motion:
    """name: label; fps: frames per second.

    root_offset: (N, 3) m, root displacement in the world frame from the standing rest
    position; root_rotation: (N, 3, 3) body frame -> world; angles: (N, 29) rad within
    Table 1 (see :mod:`swarmpose.body.skeleton`).
    """

    name: str
    fps: float
    root_offset: np.ndarray
    root_rotation: np.ndarray
    angles: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.angles)
        check_shape("motion.angles", self.angles, (n, N_ANGLES))
        check_shape("motion.root_offset", self.root_offset, (n, 3))
        check_shape("motion.root_rotation", self.root_rotation, (n, 3, 3))
        if n == 0:
            raise ShapeError(f"motion {self.name!r} has no frames")
        if not (self.fps > 0):
            raise ShapeError(f"motion {self.name!r} has fps {self.fps}; it must be positive")

    def __len__(self) -> int:
        return len(self.angles)

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return len(self) / self.fps

    def within_limits(self, tol: float = 1e-9) -> bool:
        """True when every angle lies inside Table 1."""
        return bool(np.all(self.angles >= ANGLE_LIMITS[:, 0] - tol) and np.all(self.angles <= ANGLE_LIMITS[:, 1] + tol))
