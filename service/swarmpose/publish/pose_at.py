"""A frame message's poses moved on to another moment by their joints' velocities, so that a
client shows where the person is now, not where they were when the frame was taken.

Each joint of a ``swarmpose.frame`` message carries ``velocity_m_s`` (m/s, in the message's
coordinates, from the body's last tracked frames). The joints at wall-clock time ``t`` are the
joints plus velocity × (t − ``received_ns``, the wall-clock time the frame was taken from the
camera), the time capped at :data:`HORIZON_S`: a straight line is a guess about the present, not
about the next second.
"""

from __future__ import annotations

import time

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS

HORIZON_S = 0.1
"""The longest time a pose is moved on (s); later moments get the pose of that one: the velocities of
poses tracked a few times a second are rough, and a longer line leads away from the person."""


def extrapolate(joints: np.ndarray, velocities: np.ndarray, dt_s: float) -> np.ndarray:
    """Joints (J, 3) m moved by velocities (J, 3) m/s over ``dt_s`` seconds (clipped to
    0..:data:`HORIZON_S`); a NaN velocity moves nothing."""
    dt = float(np.clip(dt_s, 0.0, HORIZON_S))
    return np.asarray(joints, float) + dt * np.nan_to_num(np.asarray(velocities, float))


def pose_at(message: dict, t_ns: int | None = None) -> dict[int, dict[str, list[float] | None]]:
    """Every tracked body of frame ``message`` at wall-clock time ``t_ns`` (default: now): body
    id -> joint name -> position [x, y, z] m (None where the message has none)."""
    now = time.time_ns() if t_ns is None else int(t_ns)
    dt_s = (now - int(message["received_ns"])) * 1e-9
    out = {}
    for k, body in enumerate(message.get("bodies", [])):
        if body.get("state") == "lost":
            continue
        named = body.get("joints") or {}
        joints = {}
        for name in EVAL_JOINTS:
            joint = named.get(name) or {}
            position = joint.get("position_m")
            if position is None:
                joints[name] = None
                continue
            velocity = joint.get("velocity_m_s") or [0.0, 0.0, 0.0]
            joints[name] = [round(float(x), 6) for x in extrapolate(np.array(position), np.array(velocity), dt_s)]
        out[int(body.get("id", k))] = joints
    return out
