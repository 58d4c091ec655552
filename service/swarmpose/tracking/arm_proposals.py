"""Arm proposals: particles with one arm sent where the depth or the other arm says it may be.

The per-frame search explores ±0.25-1.2 rad around the last solution, so an arm the track holds
far from the person's is found again only if the detector's keypoints pull it there. Where they
do not:

* seen from the side with the arms held out, the near arm points at the camera; the detector
  scores its elbow and wrist below ``min_score``, the depth shows forearm and hand in front of
  the chest, and the track can hold the arm raised in the image plane although the true pose
  scores better on the objective;
* the far arm of that view is hidden behind the torso: nothing observed places it;
* in a fast punch the fist moves farther between two frames than the search reaches, and the
  track's wrist trails it along the line of sight.

So every frame, with the last solution posed:

* **reach**: per arm, the observed points within the arm's bones plus a hand
  (:data:`HAND_M`) of its shoulder, on its side of the torso's middle plane (up to
  :data:`ACROSS_M` past it), that lie farther than :data:`EXPLAINED_M` from the posed body's
  surface; if they cover at least :data:`MIN_AREA_M2`, the cluster farthest from the
  shoulder becomes the wrist's target (:data:`JOINT_BEHIND_M` behind the surface, within reach),
  with the elbow where the two bones meet nearest the last elbow, and with the arm straight
  towards it;
* **mirror**: per arm, the other arm's elbow and wrist reflected through the torso's middle
  plane (people hop, clap, swing and lift with both arms alike; a hidden arm has nothing
  better to go by).

Each arm's four angles are solved to its targets (:func:`~swarmpose.tracking.limb_flips.solve_limbs`,
from the last pose and from the arm at rest, the closer kept), and each candidate that reaches
them joins the swarm as a particle: the objective decides, as with the limb flips.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.open3d_import import open3d
from swarmpose.tracking.body_scene import body_scene
from swarmpose.tracking.limb_flips import FLIP_LIMBS, MAX_MISS_M, limb_columns, solve_limbs

REACH_ARMS: tuple[tuple[str, str, str], ...] = tuple(limb for limb in FLIP_LIMBS if limb[0].endswith("_shoulder"))
"""Per arm, left first: the (pivot, middle, end) points of :data:`~swarmpose.tracking.limb_flips.FLIP_LIMBS`'s arms."""
EXPLAINED_M = 0.10
"""An observed point this close to the posed (decimated) body's surface is explained by it: the
depth noise is 1-3 cm at 3 m, the decimated mesh cuts corners by a few cm, and the limbs move
between frames."""
MIN_AREA_M2 = 0.002
"""Unexplained surface within an arm's reach smaller than this (20 cm²; a forearm and hand seen end
on show 30-60) is noise or a fringe of the silhouette, not an arm."""
CLUSTER_M = 0.12
"""The target is the mean of the unexplained points within this distance of the farthest one
(by its 90th percentile of distance from the shoulder)."""
HAND_M = 0.15
"""The hand reaches this far beyond the wrist: the points an arm may explain lie within its bones'
length plus this of the shoulder."""
ACROSS_M = 0.10
"""An arm reaches for points on its own side of the torso's middle plane or at most this far past
it: seen from the side, the far arm's reach takes in the near arm's surface in front of the chest,
and a far arm sent there through the chest drew a dance's track into a mirrored facing."""
REACH_SHARE = 0.98
"""A wrist target farther than this share of the arm's reach is drawn in to it: a straight arm
sits on its joint limit, where the Gauss-Newton solve stalls."""
JOINT_BEHIND_M = 0.03
"""The wrist joint lies this far behind the surface the camera sees (the hand's half thickness)."""
MAX_POINTS = 4000
"""The depth inside the box is sampled on a regular grid of about this many points (the grid step
is rounded up to whole pixels, so a few more at most)."""


def surface_distance(scene, points: np.ndarray) -> np.ndarray:
    """(N,) m: the distance of each point (N, 3) m to the posed body of ``scene``
    (:func:`~swarmpose.tracking.body_scene.body_scene`; Open3D's exact point-to-triangle distance:
    a vertex's distance would miss by half the decimated mesh's 5-10 cm edges)."""
    o3d = open3d()

    return scene.compute_distance(o3d.core.Tensor(np.ascontiguousarray(points, np.float32))).numpy().astype(float)


def observed_points(depth: np.ndarray, intrinsics: Intrinsics,
                    box: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The valid depth (H, W) m inside ``box`` (u0, v0, width, height) px, sampled on a regular
    grid of about :data:`MAX_POINTS`: the points (N, 3) m in the camera frame and the area (N,)
    m² of the surface each one stands for (its grid cell seen at its depth)."""
    h, w = depth.shape
    u0, v0 = max(int(box[0]), 0), max(int(box[1]), 0)
    u1, v1 = min(int(np.ceil(box[0] + box[2])), w), min(int(np.ceil(box[1] + box[3])), h)
    if u1 <= u0 or v1 <= v0:
        return np.zeros((0, 3)), np.zeros(0)
    stride = max(1, int(np.ceil(np.sqrt((u1 - u0) * (v1 - v0) / MAX_POINTS))))
    v, u = np.mgrid[v0:v1:stride, u0:u1:stride]
    z = depth[v, u].astype(np.float64)
    ok = np.isfinite(z) & (z > 0)
    u, v, z = u[ok], v[ok], z[ok]
    points = np.stack([(u - intrinsics.cx) / intrinsics.fx * z, (v - intrinsics.cy) / intrinsics.fy * z, z], axis=1)
    area = (stride * z) ** 2 / (intrinsics.fx * intrinsics.fy)
    return points, area


def elbow_between(shoulder: np.ndarray, wrist: np.ndarray, upper: float, lower: float,
                  near: np.ndarray) -> np.ndarray:
    """The elbow (3,) m at ``upper`` m from ``shoulder`` and ``lower`` m from ``wrist`` (all (3,)) that
    is nearest ``near`` (3,): on the circle where the two spheres meet (the straight arm's point
    when the wrist is at full reach or beyond; for a wrist nearer the shoulder than the bones'
    difference, the circle of the arm folded as far as it goes, in the wrist's direction)."""
    axis = wrist - shoulder
    d = float(np.linalg.norm(axis))
    if d < 1e-9:
        return shoulder + upper * np.array([0.0, 1.0, 0.0])
    axis = axis / d
    if d >= upper + lower:
        return shoulder + upper * axis
    d = max(d, abs(upper - lower))  # a wrist nearer than the bones can fold: as folded as they go
    along = (d * d + upper * upper - lower * lower) / (2.0 * d)
    radius = np.sqrt(max(upper * upper - along * along, 0.0))
    centre = shoulder + along * axis
    side = (near - centre) - ((near - centre) @ axis) * axis
    if np.linalg.norm(side) < 1e-9:  # the last elbow on the axis: any side, across the least parallel camera axis
        side = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    return centre + radius * side / np.linalg.norm(side)


def wrist_target(points: np.ndarray, area: np.ndarray, shoulder: np.ndarray, reach: float) -> np.ndarray | None:
    """Where an arm of ``reach`` m from ``shoulder`` (3,) would put its wrist to explain the
    unexplained points (N, 3) with their areas (N,) m²: the cluster farthest from the shoulder
    among the points within ``reach`` + :data:`HAND_M`, moved :data:`JOINT_BEHIND_M` away from the
    camera and drawn in to :data:`REACH_SHARE` of the reach; None when those points cover less
    than :data:`MIN_AREA_M2`."""
    distance = np.linalg.norm(points - shoulder, axis=1)
    near = distance <= reach + HAND_M
    if area[near].sum() < MIN_AREA_M2:
        return None
    points, distance = points[near], distance[near]
    far = points[int(np.argmin(np.abs(distance - np.percentile(distance, 90))))]
    target = points[np.linalg.norm(points - far, axis=1) <= CLUSTER_M].mean(axis=0)
    target = target + JOINT_BEHIND_M * target / np.linalg.norm(target)
    offset = target - shoulder
    length = float(np.linalg.norm(offset))
    return target if length <= REACH_SHARE * reach else shoulder + REACH_SHARE * reach * offset / length


def middle_plane(at: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """The torso's middle plane from the named points ``at`` (name -> (3,) m): a point (3,), the
    shoulders' midpoint, and its unit normal (3,) towards the left shoulder; None when the
    shoulders coincide."""
    left, right = at["left_shoulder"], at["right_shoulder"]
    normal = left - right
    length = float(np.linalg.norm(normal))
    return None if length < 1e-6 else (0.5 * (left + right), normal / length)


def on_own_side(points: np.ndarray, at: dict[str, np.ndarray], arm: tuple[str, str, str]) -> np.ndarray:
    """(N,) bool: the points (N, 3) m on ``arm``'s side of the torso's :func:`middle_plane` or at
    most :data:`ACROSS_M` past it, from the named points ``at`` (name -> (3,) m); all of them when
    the shoulders coincide."""
    plane = middle_plane(at)
    if plane is None:
        return np.ones(len(points), bool)
    side = (points - plane[0]) @ plane[1]
    return (side if arm[0] == "left_shoulder" else -side) >= -ACROSS_M


def mirrored_arm_targets(at: dict[str, np.ndarray]) -> list[tuple[tuple[str, str, str], np.ndarray]]:
    """Per arm, its (elbow, wrist) targets (2, 3) m: the other arm's reflected through the torso's
    :func:`middle_plane`, from the named points ``at`` (name -> (3,) m); only where the mirrored
    wrist lies :data:`EXPLAINED_M` or more from the arm's own wrist."""
    plane = middle_plane(at)
    if plane is None:
        return []
    middle, normal = plane
    out = []
    for arm, other in zip(REACH_ARMS, REACH_ARMS[::-1]):
        target = np.stack([p - 2.0 * ((p - middle) @ normal) * normal for p in (at[other[1]], at[other[2]])])
        if np.linalg.norm(target[1] - at[arm[2]]) >= EXPLAINED_M:
            out.append((arm, target))
    return out


def solved_arms(body: SkinnedBody, pose: np.ndarray, limbs: list[tuple[str, str, str]],
                targets: np.ndarray) -> list[np.ndarray]:
    """Copies (36,) of ``pose`` (36,) with each arm of ``limbs`` solved to its (elbow, wrist) targets
    (K, 2, 3) m, those that reach within :data:`~swarmpose.tracking.limb_flips.MAX_MISS_M`. Solved
    from the last pose and from the arm at rest (one batch), the closer kept: Gauss-Newton from an
    arm a swing away can stall on a joint limit."""
    if not limbs:
        return []
    k = len(limbs)
    starts = np.repeat(pose[None], 2 * k, axis=0)
    for i, arm in enumerate(limbs):
        cols = limb_columns(arm)
        starts[k + i, cols] = body.rest_angles[cols - 7]
    solved, miss = solve_limbs(body, starts, list(limbs) * 2, np.concatenate([targets, targets]))
    rest_better = miss[k:] < miss[:k]
    best = np.where(rest_better[:, None], solved[k:], solved[:k])
    return [p for p, m in zip(best, np.minimum(miss[:k], miss[k:])) if m <= MAX_MISS_M]


def arm_proposals(body: SkinnedBody, pose: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics,
                  box: tuple[float, float, float, float], scene=None) -> list[np.ndarray]:
    """Copies (36,) of ``pose`` (36,) with one arm moved (module doc): to the observed depth (H, W) m
    inside ``box`` (u0, v0, width, height) px that the posed body does not explain, and to the
    other arm's mirror image; at most three per arm. scene: the posed body's
    :func:`~swarmpose.tracking.body_scene.body_scene` when the caller has it (None: built here)."""
    pose = np.asarray(pose, dtype=np.float64)
    names = tuple(n for arm in REACH_ARMS for n in arm)
    at = dict(zip(names, body.posed_points(pose[None], names)[0]))
    proposals = mirrored_arm_targets(at)
    points, area = observed_points(depth, intrinsics, box)
    if len(points):
        far = surface_distance(body_scene(body, pose) if scene is None else scene, points) > EXPLAINED_M
        points, area = points[far], area[far]
    for arm in REACH_ARMS if area.sum() >= MIN_AREA_M2 else ():
        shoulder, elbow, wrist = (at[n] for n in arm)
        upper, lower = float(np.linalg.norm(elbow - shoulder)), float(np.linalg.norm(wrist - elbow))
        own = on_own_side(points, at, arm)
        target = wrist_target(points[own], area[own], shoulder, upper + lower)
        if target is not None and np.linalg.norm(target - wrist) >= EXPLAINED_M:
            # the elbow bent as the last one was, and the arm straight at the target (a reach or a punch)
            proposals.append((arm, np.stack([elbow_between(shoulder, target, upper, lower, elbow), target])))
            direction = (target - shoulder) / np.linalg.norm(target - shoulder)
            proposals.append((arm, shoulder + np.outer([upper, upper + lower], direction)))
    if not proposals:
        return []
    return solved_arms(body, pose, [arm for arm, _ in proposals], np.asarray([t for _, t in proposals]))
