"""Procedural motions that need no mocap file: wave, squat, walk, turn, jumping jacks.

Each motion is a smooth periodic function of time ``t = k / fps`` (seconds) written
directly as the 29 Table 1 angles of :mod:`swarmpose.body.skeleton`, clipped to their
limits, plus a root offset and rotation in the :class:`~swarmpose.motion.sequence.Motion` world
frame (X left, Y up, Z forward, metres). Every angle zero is the T-pose; the motions
start from a relaxed stance with the arms hanging down and out (:data:`ARMS_DOWN`) and
the elbows slightly bent (:data:`ELBOW_REST`). Axis signs used below (see the skeleton docstring):
hip pitch > 0 swings the thigh forward, knee pitch < 0 flexes, left shoulder roll > 0 and
right shoulder roll < 0 raise the arm in the frontal plane, left shoulder yaw < 0 and
right > 0 swing it forward, left elbow yaw < 0 and right > 0 flex, left hip roll > 0
and right < 0 abduct, ankle pitch < 0 lifts the toes.

Root offsets that keep the feet on the floor (the squat sinks and moves the hips back,
spread legs in jumping jacks lower them) assume a typical adult leg: thigh and shin of
0.43 m each (:data:`THIGH_LENGTH`, :data:`SHIN_LENGTH`), the ankle
:data:`ANKLE_OUTSET` outside the hip joint. Bodies with other proportions lift or sink
their feet by a centimetre or two at the extremes (about 1.5 cm for the MakeHuman body).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from swarmpose.body.kinematics import axis_angle_matrix
from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLE_NAMES, N_ANGLES
from swarmpose.core.errors import ConfigError
from swarmpose.motion.sequence import Motion

THIGH_LENGTH = 0.43
"""Hip-to-knee length (m) of the typical adult the root offsets are computed for."""
SHIN_LENGTH = 0.43
"""Knee-to-ankle length (m) of the typical adult the root offsets are computed for."""
ANKLE_OUTSET = 0.08
"""How far (m) each ankle stands outside its hip joint in the rest pose (A-pose stance)."""

ARMS_DOWN = 1.2
"""Shoulder roll (rad) below the T-pose of the relaxed stance: left -1.2, right +1.2."""
ELBOW_REST = 0.2
"""Elbow flexion (rad) of the relaxed stance: left yaw -0.2, right +0.2."""

KNEES_OUT = 0.1
"""Hip abduction (rad) at the bottom of a squat: the knees track out over the feet."""

PERIODS: dict[str, float] = {"wave": 0.8, "squat": 3.0, "walk": 1.2, "jumping_jacks": 1.2}
"""Seconds per cycle of each periodic motion; "turn" makes one revolution over the whole clip."""

_Frames = tuple[np.ndarray, np.ndarray, np.ndarray]  # angles (N, 29), root offset (N, 3), root rotation (N, 3, 3)


def _blank(n: int) -> _Frames:
    """N frames of the relaxed stance, root at rest."""
    angles = np.zeros((n, N_ANGLES))
    for side, sign in (("left", -1.0), ("right", 1.0)):
        angles[:, ANGLE_NAMES.index(f"{side}_shoulder.roll")] = sign * ARMS_DOWN
        angles[:, ANGLE_NAMES.index(f"{side}_elbow.yaw")] = sign * ELBOW_REST
    return angles, np.zeros((n, 3)), np.broadcast_to(np.eye(3), (n, 3, 3)).copy()


def relaxed_stance() -> np.ndarray:
    """The (29,) angles of the relaxed stance every motion starts from."""
    return _blank(1)[0][0]


def _set(angles: np.ndarray, name: str, values) -> None:
    """Write ``values`` (N,) or a scalar to the Table 1 angle called ``name``, e.g. "left_knee.pitch"."""
    angles[:, ANGLE_NAMES.index(name)] = values


def _cycle(name: str, t: np.ndarray) -> np.ndarray:
    """Phase ``2 pi t / period`` (rad) of a periodic motion."""
    return 2.0 * np.pi * t / PERIODS[name]


def _leg_drop(hip_flexion: np.ndarray, shin_tilt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far the hip sinks (m, >= 0) and how far the ankle lies ahead of it (m) in a flexed leg.

    The thigh leans ``hip_flexion`` rad forward of vertical and the shin ``shin_tilt`` rad
    (knee ahead of the ankle); the ankle lies ``L1 sin(hip) - L2 sin(shin)`` ahead of
    the hip and ``L1 cos(hip) + L2 cos(shin)`` below it.
    """
    sink = THIGH_LENGTH * (1 - np.cos(hip_flexion)) + SHIN_LENGTH * (1 - np.cos(shin_tilt))
    ahead = THIGH_LENGTH * np.sin(hip_flexion) - SHIN_LENGTH * np.sin(shin_tilt)
    return sink, ahead


def _abducted_height(height: np.ndarray, abduction: np.ndarray) -> np.ndarray:
    """Height (m) of the hip above the ankle after abducting a leg by ``abduction`` rad.

    Before, the ankle is ``height`` below the hip and :data:`ANKLE_OUTSET` outside it;
    the roll turns that vector about the forward axis through the hip.
    """
    return height * np.cos(abduction) - ANKLE_OUTSET * np.sin(abduction)


def _wave(t: np.ndarray) -> _Frames:
    """Right arm raised to the side (a little above the shoulder) and the forearm waving."""
    angles, offset, rotation = _blank(len(t))
    _set(angles, "right_shoulder.roll", -0.45)  # ~25 deg above horizontal
    _set(angles, "right_shoulder.pitch", -1.5)  # twist so that elbow flexion lifts the forearm
    _set(angles, "right_shoulder.yaw", 0.2)  # slightly in front of the frontal plane
    _set(angles, "right_elbow.yaw", 1.0 + 0.5 * np.sin(_cycle("wave", t)))
    return angles, offset, rotation


def _squat(t: np.ndarray) -> _Frames:
    """Knees and hips flex together while the root sinks so the feet stay flat on the floor."""
    angles, offset, rotation = _blank(len(t))
    depth = 0.5 - 0.5 * np.cos(_cycle("squat", t))  # 0 standing .. 1 at the bottom
    hip = 1.0 * depth
    shin = 0.55 * depth  # forward lean of the shin, taken up at the ankle
    for side, fwd in (("left", -1.0), ("right", 1.0)):
        _set(angles, f"{side}_hip.pitch", hip)
        _set(angles, f"{side}_hip.roll", -fwd * KNEES_OUT * depth)
        _set(angles, f"{side}_knee.pitch", -(hip + shin))
        _set(angles, f"{side}_ankle.pitch", -shin)
        _set(angles, f"{side}_shoulder.yaw", fwd * 1.3 * depth)  # arms forward for balance ...
        _set(angles, f"{side}_shoulder.roll", fwd * ARMS_DOWN * (1 - depth))  # ... and up to horizontal
    _set(angles, "spine.pitch", 0.35 * depth)
    sink, ahead = _leg_drop(hip, shin)
    leg = THIGH_LENGTH + SHIN_LENGTH
    offset[:, 1] = -(leg - _abducted_height(leg - sink, KNEES_OUT * depth))
    offset[:, 2] = -ahead  # the hips move back over the feet
    return angles, offset, rotation


def _walk(t: np.ndarray) -> _Frames:
    """Walking in place: alternate knee lifts, counter-swinging arms, a small spine twist."""
    angles, offset, rotation = _blank(len(t))
    swing = np.sin(_cycle("walk", t))  # > 0: left leg lifted
    for side, lift in (("left", np.maximum(swing, 0.0) ** 2), ("right", np.maximum(-swing, 0.0) ** 2)):
        _set(angles, f"{side}_hip.pitch", 0.75 * lift)
        _set(angles, f"{side}_knee.pitch", -1.1 * lift)
    # Each arm swings forward with the opposite leg (left yaw < 0 and right yaw > 0 are forward).
    _set(angles, "left_shoulder.yaw", 0.35 * swing)
    _set(angles, "right_shoulder.yaw", 0.35 * swing)
    _set(angles, "left_elbow.yaw", -0.3 - 0.2 * np.maximum(swing, 0.0))
    _set(angles, "right_elbow.yaw", 0.3 + 0.2 * np.maximum(-swing, 0.0))
    _set(angles, "spine.yaw", 0.1 * swing)
    return angles, offset, rotation


def _turn(t: np.ndarray, duration: float) -> _Frames:
    """Standing in the rest pose while the root turns one full revolution about the vertical."""
    angles, offset, _ = _blank(len(t))
    rotation = axis_angle_matrix((0.0, 1.0, 0.0), 2.0 * np.pi * t / duration)
    return angles, offset, rotation


def _jumping_jacks(t: np.ndarray) -> _Frames:
    """Arms sweep up over the head (shoulder roll) as the legs spread (hip roll), with a hop."""
    angles, offset, rotation = _blank(len(t))
    phase = _cycle("jumping_jacks", t)
    spread = 0.5 - 0.5 * np.cos(phase)  # 0 closed .. 1 open
    abduction = 0.35 * spread
    _set(angles, "left_shoulder.roll", -ARMS_DOWN + 2.9 * spread)  # from hanging to over the head
    _set(angles, "right_shoulder.roll", ARMS_DOWN - 2.9 * spread)
    _set(angles, "left_hip.roll", abduction)
    _set(angles, "right_hip.roll", -abduction)
    # Airborne between the closed and open stances; spread legs lower the hips to keep the feet down.
    leg = THIGH_LENGTH + SHIN_LENGTH
    hop = 0.08 * np.sin(phase) ** 2
    offset[:, 1] = hop - (leg - _abducted_height(leg, abduction))
    return angles, offset, rotation


_GENERATORS: dict[str, Callable[[np.ndarray, float], _Frames]] = {
    "wave": lambda t, _: _wave(t),
    "squat": lambda t, _: _squat(t),
    "walk": lambda t, _: _walk(t),
    "turn": _turn,
    "jumping_jacks": lambda t, _: _jumping_jacks(t),
}

BUILTIN_MOTIONS: tuple[str, ...] = tuple(_GENERATORS)
"""Names accepted by :func:`builtin_motion`."""


def builtin_motion(name: str, frames: int, fps: float = 30.0) -> Motion:
    """The procedural motion ``name`` sampled at ``t = k / fps`` for ``k < frames``.

    Returns a :class:`Motion` with angles (frames, 29) rad inside Table 1, root_offset
    (frames, 3) m and root_rotation (frames, 3, 3). Raises ConfigError for an unknown
    name, ``frames < 1`` or a non-positive ``fps``.
    """
    if name not in _GENERATORS:
        raise ConfigError(f"unknown built-in motion {name!r}; choose one of {', '.join(BUILTIN_MOTIONS)}")
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
        raise ConfigError(f"motion {name!r} needs a whole number of frames >= 1, got {frames!r}")
    if not (isinstance(fps, (int, float, np.number)) and np.isfinite(fps) and fps > 0):
        raise ConfigError(f"motion {name!r} needs a positive frame rate, got fps={fps!r}")
    t = np.arange(int(frames)) / float(fps)
    angles, offset, rotation = _GENERATORS[name](t, int(frames) / float(fps))
    angles = np.clip(angles, ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    return Motion(name=name, fps=float(fps), root_offset=offset, root_rotation=rotation, angles=angles)
