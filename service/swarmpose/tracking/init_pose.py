"""A body pose from lifted 3D joints alone: the torso frame of J^e (no manual initialisation).

The root orientation comes from the hips and shoulders: the body's left axis from the
right to the left hip and shoulder, its up axis from the mid-hip to the mid-shoulder,
orthonormalised (Gram–Schmidt, left first). The root position puts the body's own
mid-hip (at its rest angles) on the lifted mid-hip. The joint angles are the caller's
(the previous solution's, or the body's rest angles).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from swarmpose.body.kinematics import axis_angle_matrix, matrix_to_quaternion, quaternion_to_matrix
from swarmpose.body.skinned import SkinnedBody

TORSO = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
NO_TORSO = "no person: no torso (both shoulders, both hips or 3 of 4) with depth"
"""The reason of a start without a :func:`torso_pose`."""


def _mid(points: dict[str, np.ndarray], a: str, b: str) -> np.ndarray | None:
    pa, pb = points.get(a), points.get(b)
    if pa is not None and pb is not None:
        return (pa + pb) / 2.0
    return pa if pa is not None else pb


CAMERA_UP = np.array([0.0, -1.0, 0.0])
"""The camera frame's up (y points down): an upper body's torso is assumed upright along it."""


def _upright_torso(body: SkinnedBody, across: np.ndarray) -> np.ndarray:
    """(3,) m: from the hips' middle to the shoulders' of ``body`` standing upright, along the
    camera's up made perpendicular to ``across`` (3,) (a shoulder or hip line)."""
    across = across / max(np.linalg.norm(across), 1e-9)
    up = CAMERA_UP - (CAMERA_UP @ across) * across
    length = np.linalg.norm((body.point("left_shoulder") + body.point("right_shoulder")) / 2.0
                            - (body.point("left_hip") + body.point("right_hip")) / 2.0)
    return length * up / max(np.linalg.norm(up), 1e-9)


def torso_enough(found: Iterable[str], pairs: bool = True) -> bool:
    """Whether the joints named in ``found`` hold enough of the torso to start a track: three of
    the four torso joints (hips, shoulders), or with ``pairs`` both shoulders or both hips."""
    torso = set(found) & set(TORSO)
    both = [f"left_{j}" in torso and f"right_{j}" in torso for j in ("shoulder", "hip")]
    return len(torso) >= 3 or (pairs and any(both))


def torso_pose(body: SkinnedBody, lifted: dict[str, np.ndarray], angles: np.ndarray,
               upright: bool = True) -> np.ndarray | None:
    """A (36,) pose whose torso matches lifted joints {name: (3,) m}, or None when fewer than
    three of the four torso joints (hips, shoulders) have a finite lift and not both
    shoulders or both hips. angles: (29,) rad.

    With both shoulders but no hip (an upper body filling the frame: a desk, a close camera),
    or both hips but no shoulder (shoulders out of view or hidden behind someone), and
    ``upright`` (starts; not a running track, where a bending person is not upright) the torso
    is assumed upright: the missing pair's middle sits the body's torso length below (above)
    the other's, along the camera's up made perpendicular to the pair's line (the search then
    fits any lean)."""
    pts = {k: np.asarray(v, float) for k, v in lifted.items() if k in TORSO and np.all(np.isfinite(v))}
    shoulders = upright and "left_shoulder" in pts and "right_shoulder" in pts
    hips = upright and "left_hip" in pts and "right_hip" in pts
    if not torso_enough(pts, upright):
        return None
    lefts = [pts[f"left_{j}"] - pts[f"right_{j}"] for j in ("hip", "shoulder")
             if f"left_{j}" in pts and f"right_{j}" in pts]
    hip, shoulder = _mid(pts, "left_hip", "right_hip"), _mid(pts, "left_shoulder", "right_shoulder")
    if hip is None and shoulders:
        hip = shoulder - _upright_torso(body, pts["left_shoulder"] - pts["right_shoulder"])
    elif shoulder is None and hips:
        shoulder = hip + _upright_torso(body, pts["left_hip"] - pts["right_hip"])
    if not lefts or hip is None or shoulder is None:
        return None
    left = np.sum([v / max(np.linalg.norm(v), 1e-9) for v in lefts], axis=0)
    up = shoulder - hip
    if np.linalg.norm(left) < 1e-6 or np.linalg.norm(up) < 1e-6:
        return None
    x = left / np.linalg.norm(left)
    y = up - (up @ x) * x
    if np.linalg.norm(y) < 1e-6:
        return None
    y /= np.linalg.norm(y)
    rotation = np.stack([x, y, np.cross(x, y)], axis=1)  # body axes as camera-frame columns
    q = matrix_to_quaternion(rotation)
    body_mid_hip = (body.point("left_hip") + body.point("right_hip")) / 2.0
    root = body.bone_heads[0]
    translation = hip - rotation @ (body_mid_hip - root)
    h = np.concatenate([translation, q, np.asarray(angles, float)])
    # The rest angles move the hips a little relative to the root; correct with one FK pass.
    posed_mid = body.posed_points(h[None], ("left_hip", "right_hip"))[0].mean(axis=0)
    h[:3] += hip - posed_mid
    return h


FACINGS_DEG: tuple[float, ...] = (0.0, 180.0, 90.0, -90.0)
"""Turns about the body's up axis the start tries (the J^e torso facing, its back, its sides)."""


def turned(body: SkinnedBody, pose: np.ndarray, degrees: float) -> np.ndarray:
    """A copy of ``pose`` (36,) turned by ``degrees`` about the body's own up axis through its
    mid-hip: the same angles and mid-hip position, facing elsewhere."""
    h = np.array(pose, dtype=float)
    if degrees % 360.0 == 0.0:
        return h
    rotation = quaternion_to_matrix(h[3:7])
    up = rotation[:, 1]
    turn = axis_angle_matrix(up / np.linalg.norm(up), np.radians(degrees))
    mid_before = body.posed_points(h[None], ("left_hip", "right_hip"))[0].mean(axis=0)
    q = matrix_to_quaternion(turn @ rotation)
    h[3:7] = q * np.sign(q @ h[3:7] + 1e-12)
    h[:3] += mid_before - body.posed_points(h[None], ("left_hip", "right_hip"))[0].mean(axis=0)
    return h
