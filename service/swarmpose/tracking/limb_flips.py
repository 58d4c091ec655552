"""Depth flips of the limbs: poses that keep a limb's image and mirror it along the line of sight.

One depth camera and a 2D detector leave a limb's depth ambiguous wherever the depth tile
hardly sees it: an upper arm pointing at the camera and one pointing away project to the
same pixels, and so do a forearm folded towards the camera and one folded away. Once the
track has one of the two, the other is a whole limb's swing away, and the per-frame search
(±0.25-1.2 rad around the last solution) rarely crosses it: a wrist can then sit well behind
or in front of the true one along the line of sight while its image fits.

So every frame, each limb (arm: shoulder → elbow → wrist; leg: hip → knee → ankle) of the
previous solution is flipped in depth, as the kinematic jump sampling of monocular trackers
does (Sminchisescu & Triggs, CVPR 2003): the middle joint moves to the other point of its
camera ray at the same distance from the pivot (the mirror of the bone through the plane
across the line of sight), the end joint then to either point of its own ray at its bone's
length from the new middle joint; or the end joint alone flips around the middle one. Each
flipped limb's angles are solved by a few damped Gauss-Newton steps (numpy forward
kinematics, all candidates in one batch, cheap next to the search; shins below the
camera included: they lean out of the plane across their rays, but their mirror would bend the
knee forwards, so they are solved and dropped), and a candidate that reaches its joints within :data:`MAX_MISS_M` joins
the frame's swarm as a particle. The objective decides: a flip that explains the depth
better wins at once, one that does not costs nothing but the particle it replaced.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmpose.body.skeleton import ANGLE_LIMITS, angle_offset
from swarmpose.body.skinned import SkinnedBody

FLIP_LIMBS: tuple[tuple[str, str, str], ...] = tuple(
    (f"{side}_{a}", f"{side}_{b}", f"{side}_{c}")
    for side in ("left", "right") for a, b, c in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle")))
"""Per limb: its (pivot, middle, end) points; the tracking joints named like the pivot (3 angles)
and the middle point (1 angle) place the other two."""

MIN_TILT_RAD = 0.25
"""A bone is flipped only when it leaves the plane across its line of sight by at least this angle: its
mirror is then a turn of twice that, beyond the per-frame search's base half-width
(:data:`~swarmpose.tracking.search.ANGLE_RADIUS`). A limb across the line of sight (arms hanging at
the sides of a person facing the camera) has no flip worth a particle."""
SAME_M = 0.05
"""Two flipped end points closer than this are one candidate."""
MAX_MISS_M = 0.04
"""A solved flip whose joints end farther than this from their targets (joint limits) is dropped."""
STEPS = 5
"""Gauss-Newton steps per solve."""
DAMPING = 1e-4
"""Levenberg-Marquardt damping (m² per rad²)."""
DELTA_RAD = 1e-3
"""Forward-difference step of the Jacobian."""


def limb_columns(limb: tuple[str, str, str]) -> np.ndarray:
    """The pose columns (4,) of a limb's pivot joint (3 angles) and middle joint (1 angle)."""
    pivot, middle, _ = limb
    return np.array([7 + angle_offset(pivot) + k for k in range(3)] + [7 + angle_offset(middle)])


def ray_points(point: np.ndarray, centre: np.ndarray, radius: float) -> list[np.ndarray]:
    """The points (3,) of the camera ray through ``point`` (3,) m at ``radius`` m from ``centre`` (3,):
    two, or the ray's nearest point to ``centre`` when the ray misses the sphere."""
    ray = point / np.linalg.norm(point)
    along = float(ray @ centre)
    disc = along * along - float(centre @ centre) + radius * radius
    if disc <= 0.0:
        return [ray * along]
    root = np.sqrt(disc)
    return [ray * (along - root), ray * (along + root)]


def tilted(start: np.ndarray, stop: np.ndarray) -> bool:
    """Whether the bone ``start`` → ``stop`` (3,) m leaves the plane across the line of sight to
    ``stop`` by :data:`MIN_TILT_RAD` or more."""
    bone, distance = stop - start, float(np.linalg.norm(stop))
    length = float(np.linalg.norm(bone))
    if not (length > 0.0 and distance > 0.0):  # no bone, a point at the camera, or NaN
        return False
    return abs(float(bone @ stop)) / distance >= np.sin(MIN_TILT_RAD) * length


def other_point(point: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Of :func:`ray_points` for ``point`` (3,) on the sphere, the one farther from ``point``."""
    return max(ray_points(point, centre, radius), key=lambda p: float(np.linalg.norm(p - point)))


def flip_targets(pivot: np.ndarray, middle: np.ndarray, end: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The (middle, end) positions (3,) m of a limb's depth flips (see the module doc): the upper
    bone mirrored with the end on either point of its ray (one where the two coincide), and the
    lower bone alone mirrored; only bones that are :func:`tilted`."""
    upper, lower = np.linalg.norm(middle - pivot), np.linalg.norm(end - middle)
    out = []
    if tilted(pivot, middle):
        new_middle = other_point(middle, pivot, upper)
        ends = ray_points(end, new_middle, lower)
        if len(ends) == 2 and np.linalg.norm(ends[0] - ends[1]) < SAME_M:
            ends = ends[:1]
        out.extend((new_middle, new_end) for new_end in ends)
    if tilted(middle, end):
        out.append((middle, other_point(end, middle, lower)))
    return out


def solve_limbs(body: SkinnedBody, pose: np.ndarray, limbs: Sequence[tuple[str, str, str]],
                targets: np.ndarray, steps: int = STEPS, misses: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """K copies of ``pose`` (36,), each with one limb's 4 angles (:func:`limb_columns`) moved so
    that its middle and end points reach their targets by ``steps`` Gauss-Newton steps; ``pose``
    (K, 36): each candidate solved from its own start.

    limbs: K (pivot, middle, end) point names out of :data:`FLIP_LIMBS`; targets: (K, 2, 3) m, the
    middle's and the end's. Returns the solved poses (K, 36) and each one's larger miss (K,) m (None
    without ``misses``: one forward kinematics fewer, for a caller that keeps every solution)."""
    k = len(limbs)
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape not in ((36,), (k, 36)):
        raise ValueError(f"pose must be (36,) or ({k}, 36) for {k} limbs, got {pose.shape}")
    x = np.repeat(pose[None], k, axis=0) if pose.ndim == 1 else pose.copy()
    cols = np.stack([limb_columns(limb) for limb in limbs])
    lo, hi = ANGLE_LIMITS[cols - 7, 0], ANGLE_LIMITS[cols - 7, 1]
    names = tuple(dict.fromkeys(n for _, middle, end in limbs for n in (middle, end)))
    where = np.array([[names.index(middle), names.index(end)] for _, middle, end in limbs])
    rows = np.arange(k)[:, None]

    def reach(batch: np.ndarray) -> np.ndarray:  # (n·K, 36) -> (n, K, 6)
        pts = body.posed_points(batch, names).reshape(-1, k, len(names), 3)
        return pts[:, rows, where].reshape(len(pts), k, 6)

    goal = targets.reshape(k, 6)
    for _ in range(steps):
        batch = np.repeat(x[None], 5, axis=0)
        for d in range(4):
            batch[d + 1, np.arange(k), cols[:, d]] += DELTA_RAD
        got = reach(batch.reshape(-1, 36))
        residual = got[0] - goal
        jac = np.moveaxis((got[1:] - got[0]) / DELTA_RAD, 0, -1)  # (K, 6, 4)
        normal = np.einsum("kri,krj->kij", jac, jac) + DAMPING * np.eye(4)
        step = np.linalg.solve(normal, -np.einsum("kri,kr->ki", jac, residual)[..., None])[..., 0]
        x[rows, cols] = np.clip(x[rows, cols] + step, lo, hi)
    if not misses:
        return x, None
    miss = np.linalg.norm((reach(x)[0] - goal).reshape(k, 2, 3), axis=2).max(axis=1)
    return x, miss


def limb_flips(body: SkinnedBody, pose: np.ndarray, most: int | None = None) -> list[np.ndarray]:
    """The depth flips (36,) of the limbs of ``pose`` (36,) that reach their targets (module doc), in
    :data:`FLIP_LIMBS`' order; at most the first ``most`` candidates are solved (None: all)."""
    names = tuple(n for limb in FLIP_LIMBS for n in limb)
    at = dict(zip(names, body.posed_points(np.asarray(pose, float)[None], names)[0]))
    candidates = [(limb, target) for limb in FLIP_LIMBS for target in flip_targets(*(at[n] for n in limb))]
    candidates = candidates[:most]
    if not candidates:
        return []
    solved, miss = solve_limbs(body, pose, [limb for limb, _ in candidates],
                               np.asarray([target for _, target in candidates]))
    return [p for p, m in zip(solved, miss) if m <= MAX_MISS_M]
