"""Where a frame's swarm searches: the start region around the previous solution and the
perturbation of the perturbed PSO (paper §2.4).

* translations within ±(4 cm + the root offset J^e's torso implies) per axis, root
  rotation within ±0.15 rad;
* each limb's angles within ±(0.25 rad + the angle by which its detected joints moved away
  from the previous solution, seen from the limb's pivot, up to 1.2 rad), so the region
  holds the pose J^e implies;
* the perturbation redraws one limb's angles (an arm, a leg, or trunk and neck) within
  ±0.5 rad.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.kinematics import matrix_to_quaternion, quaternion_to_matrix, rotation_power
from swarmpose.body.skeleton import ANGLE_JOINT, ANGLE_LIMITS, ANGLES, JOINT_INDEX, POSE_DIM, ROOT_QUATERNION
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.rotations import rotvec_matrix
from swarmpose.tracking.objective import JointTargets

LIMB_GROUPS: tuple[tuple[str, ...], ...] = (
    ("left_collar", "left_shoulder", "left_elbow"), ("right_collar", "right_shoulder", "right_elbow"),
    ("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle"), ("spine", "neck"),
)
"""Tracking joints whose angles one perturbation redraws together."""

LIMB_ENDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("left_shoulder", ("left_elbow", "left_wrist")), ("right_shoulder", ("right_elbow", "right_wrist")),
    ("left_hip", ("left_knee", "left_ankle")), ("right_hip", ("right_knee", "right_ankle")),
    ("mid_hip", ("left_shoulder", "right_shoulder", "nose")),
)
"""Per limb group: the pivot and the points whose detected motion widens that limb's search."""

ANGLE_RADIUS = (0.25, 1.2)
"""Per-frame search half-width of a limb's angles (rad): the base, and the most it widens to."""

LIMB_COLUMNS: tuple[np.ndarray, ...] = tuple(
    7 + np.flatnonzero(np.isin(ANGLE_JOINT, [JOINT_INDEX[j] for j in group])) for group in LIMB_GROUPS)
"""Per limb group: its columns of the 36-D pose."""

UPRIGHT_QUATERNION = np.array([0.0, 1.0, 0.0, 0.0])


def pose_bounds() -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (36,) of the pose: free translation, quaternion entries in -1..1, Table 1's angles."""
    lo, hi = np.full(POSE_DIM, -np.inf), np.full(POSE_DIM, np.inf)
    lo[ROOT_QUATERNION], hi[ROOT_QUATERNION] = -1.0, 1.0
    lo[ANGLES], hi[ANGLES] = ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1]
    return lo, hi


def renormalise(x: np.ndarray) -> np.ndarray:
    """Poses (P, 36) with unit root quaternions (upright where one collapsed), in place."""
    q = x[:, ROOT_QUATERNION]
    n = np.linalg.norm(q, axis=1, keepdims=True)
    x[:, ROOT_QUATERNION] = np.where(n > 1e-9, q / np.maximum(n, 1e-9), UPRIGHT_QUATERNION)
    return x


def perturb(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A copy of poses (P, 36), each with one random limb's angles moved within ±0.5 rad."""
    x = x.copy()
    for i in range(len(x)):
        cols = LIMB_COLUMNS[int(rng.integers(len(LIMB_COLUMNS)))]
        x[i, cols] += rng.uniform(-0.5, 0.5, len(cols))
    return x


def spread(centre: np.ndarray, count: int, rng: np.random.Generator, t_radius: np.ndarray, rot_radius: float,
           angle_radius: float | np.ndarray) -> np.ndarray:
    """``count`` poses (count, 36) uniformly around ``centre`` (36,): translation ±t_radius (3,) m,
    root rotation ±rot_radius rad per axis, angles ±angle_radius rad (scalar or (29,);
    clipped to the limits)."""
    x = np.repeat(centre[None], count, axis=0)
    x[:, :3] += rng.uniform(-1.0, 1.0, (count, 3)) * t_radius
    turn = rotvec_matrix(rng.uniform(-rot_radius, rot_radius, (count, 3)))
    rot = turn @ quaternion_to_matrix(centre[ROOT_QUATERNION])
    q = matrix_to_quaternion(rot)
    q *= np.sign(q @ centre[ROOT_QUATERNION] + 1e-12)[:, None]  # stay in the centre's hemisphere
    x[:, ROOT_QUATERNION] = q
    x[:, 7:] += rng.uniform(-angle_radius, angle_radius, (count, 29))
    x[:, 7:] = np.clip(x[:, 7:], ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    return x


def angle_radius(body: SkinnedBody, intrinsics: Intrinsics, centre: np.ndarray, targets: JointTargets) -> np.ndarray:
    """(29,) per-angle search half-width (rad): each limb's widens with how far its detected
    joints moved from the pose ``centre`` (36,), as an angle seen from the limb's pivot."""
    radius = np.full(29, ANGLE_RADIUS[0])
    if targets.count == 0:
        return radius
    names = tuple(dict.fromkeys([p for pivot, ends in LIMB_ENDS for p in (pivot, *ends)]))
    pts = dict(zip(names, body.posed_points(centre[None], names)[0]))
    detected = dict(zip(targets.names, targets.xy))
    for (pivot, ends), cols in zip(LIMB_ENDS, LIMB_COLUMNS):
        moved = []
        for end in ends:
            if end not in detected:
                continue
            shift = np.linalg.norm(intrinsics.project(pts[end][None])[0] - detected[end])
            reach = np.linalg.norm(pts[end] - pts[pivot]) * intrinsics.fx / max(pts[end][2], 0.1)
            moved.append(shift / max(reach, 1.0))
        if moved:
            radius[cols - 7] = np.clip(ANGLE_RADIUS[0] + max(moved), *ANGLE_RADIUS)
    return radius


MAX_PREDICTED_STEPS = 4.0
"""A constant-velocity prediction looks at most this many of the last step's lengths ahead."""


def predicted_pose(previous: np.ndarray, before: np.ndarray, step_s: float, ahead_s: float) -> np.ndarray:
    """The pose (36,) ``ahead_s`` seconds after ``previous`` (36,) if it goes on as it came from
    ``before`` (36,), ``step_s`` seconds earlier: translation and joint angles moved linearly
    (angles clipped to their limits), the root turned on by the same rotation per second; at
    most :data:`MAX_PREDICTED_STEPS` steps ahead."""
    previous, before = np.asarray(previous, float), np.asarray(before, float)
    ratio = min(max(ahead_s, 0.0) / step_s, MAX_PREDICTED_STEPS) if step_s > 0 else 0.0
    out = previous.copy()
    out[:3] += ratio * (previous[:3] - before[:3])
    out[7:] = np.clip(previous[7:] + ratio * (previous[7:] - before[7:]), ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    now = quaternion_to_matrix(previous[ROOT_QUATERNION])
    turn = now @ quaternion_to_matrix(before[ROOT_QUATERNION]).T
    q = matrix_to_quaternion(rotation_power(turn, ratio) @ now)
    out[ROOT_QUATERNION] = q * np.sign(q @ previous[ROOT_QUATERNION] + 1e-12)
    return out
