"""Each published body's joint velocities, from that body's last tracked frames, so that a client
can move a pose on to its own clock (:mod:`swarmpose.publish.pose_at`).

Velocity of a body's joints = (joints − the same body's joints at its last tracked frame) / the
capture time between the two, blended with the previous estimate (:data:`BLEND`: the new
difference's share) to damp the search's frame-to-frame jitter; the first difference of a track is
taken whole. A body's first frame, a gap longer than :data:`MAX_GAP_S` and a lost body give 0 (and
start over).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from swarmpose.tracking.result import FrameResult

MAX_GAP_S = 1.0
"""Tracked frames further apart than this (s) give no velocity: the motion between them is not a line."""
BLEND = 0.5
"""The new frame difference's share of the velocity (the rest: the previous estimate)."""


class JointVelocities:
    """Estimates every body's joint velocities (m/s, camera frame) frame by frame, keyed by body id."""

    def __init__(self, max_gap_s: float = MAX_GAP_S, blend: float = BLEND):
        self.max_gap_s, self.blend = float(max_gap_s), float(blend)
        self._last: dict[int, tuple[float, np.ndarray, np.ndarray | None]] = {}  # id -> (time s, joints, velocity)

    def __call__(self, result: FrameResult) -> FrameResult:
        """``result`` with each tracked body's ``velocities`` (14, 3) m/s."""
        if not result.bodies:
            return result
        t = result.timestamp_ns * 1e-9
        bodies = []
        for body in result.bodies:
            if body.state == "lost":
                self._last.pop(body.id, None)
                bodies.append(body)
                continue
            joints = np.asarray(body.joints3d, float)
            velocity = None
            last = self._last.get(body.id)
            if last is not None and 0.0 < t - last[0] <= self.max_gap_s:
                step = (joints - last[1]) / (t - last[0])
                blended = step if last[2] is None else self.blend * step + (1 - self.blend) * last[2]
                velocity = np.where(np.isfinite(blended), blended, 0.0)
            self._last[body.id] = (t, joints, velocity)
            bodies.append(replace(body, velocities=np.zeros_like(joints) if velocity is None else velocity))
        return replace(result, bodies=tuple(bodies))

    def reset(self) -> None:
        """Forget every body's last frame."""
        self._last.clear()
