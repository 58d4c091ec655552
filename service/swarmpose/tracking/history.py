"""A track's last solutions with their capture times: seeds for the next frame's swarm, and where
their motion leads when frames were dropped in between (live)."""

from __future__ import annotations

import numpy as np

from swarmpose.body.kinematics import root_turn_deg
from swarmpose.tracking.search import predicted_pose

HISTORY = 5
"""Previous solutions kept (and injected as particles)."""
DROPPED = 1.5
"""A frame more than this many camera frame periods after the last tracked one follows dropped frames."""


class TrackHistory:
    """The last :data:`HISTORY` poses (36,) of a track and their capture times (ns)."""

    def __init__(self):
        self.poses: list[np.ndarray] = []
        self.times_ns: list[int] = []

    def __len__(self) -> int:
        return len(self.poses)

    def add(self, pose: np.ndarray, time_ns: int) -> None:
        """Keep ``pose``, captured at ``time_ns``, dropping the oldest beyond :data:`HISTORY`."""
        self.poses.append(pose)
        self.times_ns.append(int(time_ns))
        del self.poses[:-HISTORY], self.times_ns[:-HISTORY]

    def clear(self) -> None:
        """Forget every pose."""
        self.poses.clear()
        self.times_ns.clear()

    def restart(self, pose: np.ndarray, time_ns: int = 0) -> None:
        """Only ``pose`` (a track set from outside: a backward pass, a refit)."""
        self.clear()
        self.add(pose, time_ns)

    def newest_first(self) -> list[np.ndarray]:
        """The poses, newest first."""
        return self.poses[::-1]

    def periods_since(self, time_ns: int, period_s: float | None) -> float:
        """Camera frame periods (``period_s``) from the newest pose to ``time_ns``, at least 1 (1 too
        when no period is known or no pose kept)."""
        if not period_s or not self.times_ns:
            return 1.0
        return max((time_ns - self.times_ns[-1]) * 1e-9 / period_s, 1.0)

    def last_step_s(self) -> float | None:
        """Seconds from the second newest pose to the newest; None with fewer than two poses."""
        return (self.times_ns[-1] - self.times_ns[-2]) * 1e-9 if len(self.poses) >= 2 else None

    def turn_rate_deg_s(self) -> float | None:
        """How fast the root turned (deg/s, about any axis) from the second newest pose to the newest; None
        with fewer than two poses or no time between them."""
        step_s = self.last_step_s()
        if not step_s or step_s <= 0:
            return None
        return float(root_turn_deg(self.poses[-2], self.poses[-1])) / step_s

    def predicted(self, time_ns: int, periods: float, every_step: bool = False) -> list[np.ndarray]:
        """After dropped frames (``periods`` > :data:`DROPPED`), or after any step with ``every_step`` (a
        live frame, whose short search starts nearer where the body goes): the pose the last two poses'
        motion leads to at ``time_ns`` (:func:`~swarmpose.tracking.search.predicted_pose`), as a seed;
        else none."""
        step_s = self.last_step_s()
        if (periods <= DROPPED and not every_step) or step_s is None:
            return []
        return [predicted_pose(self.poses[-1], self.poses[-2], step_s, (time_ns - self.times_ns[-1]) * 1e-9)]
