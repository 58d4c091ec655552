"""The paper's objective ``E = w_D·E_D + w_J·E_J`` (§2.3), plus our ``w_P·E_P``, evaluated for
all particles at once.

Units (chosen so that the paper's balance w_D = 3, w_J = 1, α = 0.97 works):

* ``E_D = (1/N_P) Σ_{p∈B} min(|d^h_p − d^o_p|, T)`` in **centimetres**: the OpenCL scorer's
  per-particle sum over the observed pixels of the tile over B (invalid depth ignored,
  T = 0.30 m), divided by N_P = the number of tile pixels where the *reference* pose (the
  previous solution, or the initial guess on the first frame) is rendered, observed and
  within T — one normalisation shared by every particle of the frame. N_P is at least a
  tenth of the observed pixels, so a bad reference cannot inflate E_D without bound.
* ``E_J2D`` in **pixels** and ``E_J3D`` in **millimetres**: weighted means of the distances
  between the model's points (projected for 2D) and the detected 2D joints j^e / their lift
  J^e, with w = 0.2 for hips, 1.8 for wrists and ankles, 1 otherwise; joints missing from
  the detection, below ``min_score`` or without depth drop out of their term.
  The lift of an occluded joint is the occluder's surface (the far arm of a person seen from
  the side lifts onto the torso, in front of the arm). The 3D distance stays symmetric, since a
  one-sided one (free behind the lift) would let a track hold a visible arm behind the torso;
  instead (``hidden_lifts``, :mod:`swarmpose.tracking.hidden_lifts`) a limb joint's lift leaves
  the 3D term when the previous solution hides the joint *and* the depth at its keypoint shows
  that solution's occluder, so a track that wrongly holds a visible arm behind the torso keeps
  the lift that pulls it out.
* ``E_J = α·E_J2D + (1 − α)·E_J3D``, α = 0.97.
* ``E_P`` in **centimetres** (:meth:`Objective.penetration_cm`): how deep the elbows and
  wrists sink into the torso's core, a capsule from the hips' middle to the shoulders'
  middle; w_P = 1 (``penetration`` setting, 0 = off). Not in the paper: nothing else keeps
  an occluded arm out of the trunk.
* ``E_A`` in **rad²** (:meth:`Objective.arm_prior_rad2`; not in the paper): the squared
  distance of both arms' shoulder (roll, pitch, yaw) and elbow angles from the body's rest
  angles, weight w_A (``arm_prior`` setting; 0 = off, the default) times how side on the
  reference pose stands (:func:`side_on_share`: 0 facing the camera or turned
  away, 1 side on). Seen from the side, an arm that hangs over the torso or points at the
  camera is missed by the detector and hardly shows in the depth tile, and the search leaves
  it raised or swung out where nothing contradicts it; a weak pull to the rest pose puts it
  where an unobserved arm usually is. It is scaled by the side-on share so that views from
  behind and real arm motions keep their freedom, and it is opt-in because it can still pull
  a real arm away (a real upper body close below the camera, whose tilted line of sight reads
  as partly side on, for one).
* Left/right label swaps of the detector (common on people seen from behind or the side):
  with ``label_swaps``, each detected left/right pair (shoulders, elbows, ..., ears) is
  matched to the model's pair in the better of the two assignments, the crossed one at a
  cost of :data:`SWAP_COST` of the person's size (px) per joint, so the labels are trusted
  unless the crossed fit is clearly better; the 3D term uses the same assignment.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.body.skeleton import angle_offset, joint_weight
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.detect.joints import Joints2D
from swarmpose.tracking.config import MODE_WEIGHTS, tracker_default
from swarmpose.tracking.lift import lift_detection

SWAP_COST = 0.05
"""Cost of matching a detected left/right pair crossed, per joint, as a share of the person's size."""

IMAGE_MARGIN = 0.5
"""Keypoints up to this share of the image's width/height outside it still count (a foot cut
off by the frame's edge); farther ones are ignored."""

SPENT_KEYS = ("score", "joints", "calls")
"""The parts of :attr:`Objective.spent_s`."""

ARM_POINTS = ("left_elbow", "right_elbow", "left_wrist", "right_wrist")
"""The points :attr:`Objective.penetration_cm` keeps out of the torso."""

ARM_PRIOR_COLUMNS = np.array([7 + angle_offset(f"{side}_shoulder") + k for side in ("left", "right") for k in range(3)]
                             + [7 + angle_offset(f"{side}_elbow") for side in ("left", "right")])
"""The pose columns (36-D) of both shoulders' three and both elbows' angle, which E_A pulls to rest."""

TORSO_RADIUS_SHARE = 0.4
"""The torso's core, kept free of elbows and wrists, is a capsule from the hips' middle to the
shoulders' middle of radius this share of the distance between the hip joints (about 7.5 cm
on an adult): only arms clearly inside the trunk pay."""


def side_on_share(pose: np.ndarray) -> float:
    """|sin| of the angle between the body's forward axis and the line of sight to its root
    for a pose (36,): 0 facing the camera or turned away, 1 side on (E_A's scale). A line of
    sight tilted up or down counts too (a person close below the camera reads as partly side
    on), not only the body's turn about the vertical."""
    h = np.asarray(pose, float)
    sight = h[:3] / max(float(np.linalg.norm(h[:3])), 1e-9)
    cos = float(quaternion_to_matrix(h[3:7])[:, 2] @ sight)
    return float(np.sqrt(max(1.0 - cos * cos, 0.0)))


@dataclass(frozen=True)
class ObjectiveWeights:
    """w_D, w_J, α, the clamp T (m), the lowest detection score a joint needs, whether
    detected left/right pairs may match the model crossed, and w_P (per cm of an elbow or
    wrist inside the torso), w_A (per rad² of the arms' angles away from the rest pose), w_S
    (per cm of E_S, the model's pixels no observation within T confirms: the shape fit's
    silhouette term, see :mod:`~swarmpose.personalise.personalise`; 0 in tracking). E_S applies
    only where the depth term does (w_D > 0 and depth in the box)."""

    depth: float = MODE_WEIGHTS["hybrid"][0]
    joints: float = MODE_WEIGHTS["hybrid"][1]
    alpha: float = tracker_default("alpha")
    threshold_m: float = tracker_default("threshold_m")
    min_score: float = tracker_default("min_score")
    label_swaps: bool = tracker_default("label_swaps")
    penetration: float = tracker_default("penetration")
    arm_prior: float = tracker_default("arm_prior")
    silhouette: float = 0.0

    def __post_init__(self) -> None:
        for name in ("depth", "joints", "threshold_m", "penetration", "arm_prior", "silhouette"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"objective weight {name} must be finite and >= 0, got {value}")
        if not 0.0 <= self.alpha <= 1.0:
            raise ConfigError(f"alpha must be within 0..1, got {self.alpha}")
        if self.depth == 0 and self.joints == 0:
            raise ConfigError("w_D and w_J cannot both be 0")


@dataclass(frozen=True)
class JointTargets:
    """The detected joints of one frame, as the objective uses them.

    names: body points with a usable detection; point_index: (n,) into the body's named
    points; xy: (n, 2) detected pixels j^e; xyz: (n, 3) lifted J^e in m (NaN rows: no
    depth); weight: (n,) the paper's joint weights.
    """

    names: tuple[str, ...]
    point_index: np.ndarray
    xy: np.ndarray
    xyz: np.ndarray
    weight: np.ndarray

    @property
    def count(self) -> int:
        return len(self.names)

    @cached_property
    def extent_px(self) -> float:
        """The person's size in pixels: the diagonal of the detected joints' box (0 with fewer than two)."""
        return float(np.linalg.norm(np.ptp(self.xy, axis=0))) if self.count > 1 else 0.0

    @cached_property
    def pairs(self) -> np.ndarray:
        """(m, 2) indices of the targets that form a left/right pair (left first); computed once
        per frame (the joint term asks every generation)."""
        index = {n: i for i, n in enumerate(self.names)}
        found = [(i, index["right_" + n[5:]]) for n, i in index.items()
                 if n.startswith("left_") and "right_" + n[5:] in index]
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    @classmethod
    def empty(cls) -> JointTargets:
        return cls((), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros(0))

    @classmethod
    def from_detection(cls, joints: Joints2D | None, depth: np.ndarray, intrinsics: Intrinsics,
                       body: SkinnedBody, min_score: float = 0.3) -> JointTargets:
        """Targets from a detection: its body points with score >= ``min_score`` that lie within
        :data:`IMAGE_MARGIN` image sizes of the image (a keypoint farther out is a detector's
        failure, not a joint), lifted on ``depth``."""
        if joints is None:
            return cls.empty()
        w, h = intrinsics.width, intrinsics.height
        points = {k: v for k, v in joints.by_point().items() if v[2] >= min_score and k in body.point_names
                  and -IMAGE_MARGIN * w <= v[0] <= (1 + IMAGE_MARGIN) * w
                  and -IMAGE_MARGIN * h <= v[1] <= (1 + IMAGE_MARGIN) * h}
        if not points:
            return cls.empty()
        lifted = lift_detection(depth, intrinsics, joints, min_score)
        names = tuple(points)
        return cls(names, body.point_indices(names),
                   np.array([points[n][:2] for n in names], float),
                   np.array([lifted.get(n, np.full(3, np.nan)) for n in names], float),
                   np.array([joint_weight(n) for n in names], float))


def weighted_joint_distance(model: np.ndarray, target: np.ndarray, weight: np.ndarray,
                            order: np.ndarray | None = None, swap_cost: float = 0.0) -> np.ndarray:
    """(P,) weighted mean distance between model points (P, n, k) and targets (n, k); rows of
    ``target`` with NaN drop out. 0 when no target is usable. order: (P, n) which model point
    each target is matched with (None: the same index); a target matched with another index
    than its own adds ``swap_cost`` to its distance."""
    ok = np.all(np.isfinite(target), axis=1)
    if not np.any(ok):
        return np.zeros(len(model))
    matched = model if order is None else np.take_along_axis(model, order[..., None], axis=1)
    d = np.linalg.norm(matched[:, ok] - target[ok], axis=2)
    if order is not None:
        d += swap_cost * (order[:, ok] != np.flatnonzero(ok))
    w = weight[ok]
    return d @ w / w.sum()


def torso_radius(body: SkinnedBody) -> float:
    """The torso core's radius (m) E_P measures arms against: :data:`TORSO_RADIUS_SHARE` of the
    hip width."""
    return TORSO_RADIUS_SHARE * float(np.linalg.norm(body.point("left_hip") - body.point("right_hip")))


class Objective:
    """E(h, o) for batches of poses on one frame.

    Per frame call :meth:`set_frame`; then ``objective(h)`` returns E (P,) and
    :attr:`last_parts` holds E_D, E_J2D, E_J3D, E_J, E_P, E_A (and E_S where w_S > 0) (P,) of the
    last call. One launch of the scorer computes all the terms (forward kinematics, the depth
    term and the pixel counts E_S needs, and the joint and penetration terms from the named
    points, cl/include/joint_term.h, of which :meth:`host_terms` is the numpy oracle).
    :attr:`spent_s` accumulates where the calls' time went (s):
    ``score`` (the launch and its wait: forward kinematics and every term on the device),
    ``joints`` (combining the terms on the host), and ``calls``.

    ``scorer``: a :class:`~swarmpose.gpu.scorer.ParticleScorer` for the same body and
    intrinsics; ``coarse``: optionally a second one on a smaller tile and a coarser mesh, which
    :attr:`coarse_active` switches the depth term to (coarse-to-fine search; E_D is normalised
    per level, so its scale stays the same).
    """

    def __init__(self, body: SkinnedBody, intrinsics: Intrinsics, scorer,
                 weights: ObjectiveWeights = ObjectiveWeights(), coarse=None):
        self.body, self.intrinsics, self.scorer, self.weights = body, intrinsics, scorer, weights
        self.coarse = coarse
        self.coarse_active = False
        self.targets = JointTargets.empty()
        self._penetration_points = body.point_indices(ARM_POINTS + ("left_hip", "right_hip", "left_shoulder",
                                                                    "right_shoulder"))
        self.torso_radius = torso_radius(body)
        self.normaliser = 1.0
        self.coarse_normaliser = 1.0
        self.has_depth = False
        self.arm_prior_scale = 1.0
        self.last_parts: dict[str, np.ndarray] = {}
        self.last_counts: dict[str, np.ndarray] = {}
        self.spent_s = dict.fromkeys(SPENT_KEYS, 0.0)

    def set_body(self, body: SkinnedBody) -> None:
        """Score another shape of the same body (same topology; see ``ParticleScorer.set_body``)
        from now on, on the full-resolution level (a coarse level is the caller's to replace)."""
        self.scorer.set_body(body)
        self.body = body
        self.torso_radius = torso_radius(body)
        for scorer in self.levels:
            scorer.joint_targets_owner = None  # the torso radius travels with the targets

    def take_spent(self) -> dict[str, float]:
        """The time accumulated in :attr:`spent_s` since the last take, and a fresh start."""
        spent, self.spent_s = self.spent_s, dict.fromkeys(SPENT_KEYS, 0.0)
        return spent

    def use_full_resolution(self) -> None:
        """Score at full resolution from now on (the end of a coarse-to-fine search)."""
        self.coarse_active = False

    @property
    def levels(self) -> tuple:
        """The scorers: the full-resolution one, then the coarse one if any."""
        return (self.scorer,) if self.coarse is None else (self.scorer, self.coarse)

    def set_frame(self, depth: np.ndarray, box, targets: JointTargets, reference: np.ndarray) -> None:
        """Upload the observation of B, set the joint targets and N_P from the reference pose (36,)
        (per level)."""
        self.set_targets(targets)
        normalisers = []
        for scorer in self.levels:
            scorer.set_observation(depth, box)
            self._upload_targets(scorer)
            _, counts = scorer.score(np.asarray(reference, float)[None])
            observed = int(counts["observed"][0])
            normalisers.append(float(max(int(counts["close"][0]), 0.1 * observed, 1.0)))
            if scorer is self.scorer:
                self.has_depth = observed > 0
        self.normaliser, self.coarse_normaliser = normalisers[0], normalisers[-1]
        # E_A weighs by how side on the pose the search starts around stands; an objective that
        # never had a frame (the start's joint-term-only stage) weighs it in full
        self.arm_prior_scale = side_on_share(reference)

    def set_targets(self, targets: JointTargets) -> None:
        """The frame's joint targets alone: all a joint-term-only objective (w_D = 0) needs."""
        self.targets = targets

    def _upload_targets(self, scorer) -> None:
        """Give ``scorer`` this objective's targets unless it holds them already (objectives may
        share a scorer)."""
        held = scorer.joint_targets_owner
        if held is not None and held[0] is self.targets and held[1] == self.weights.label_swaps:
            return
        t = self.targets
        pairs = t.pairs if self.weights.label_swaps else np.zeros((0, 2), np.int64)
        scorer.set_joint_targets(t.xy, t.xyz, t.weight, t.point_index, pairs, self._swap_px, self.torso_radius,
                                 self._penetration_points, owner=(t, self.weights.label_swaps))

    @property
    def uses_depth(self) -> bool:
        return self.weights.depth > 0 and self.has_depth

    @property
    def uses_joints(self) -> bool:
        return self.weights.joints > 0 and self.targets.count > 0

    def arm_prior_rad2(self, h: np.ndarray) -> np.ndarray:
        """(P,) rad²: E_A of poses h (P, 36), the squared distance of the arms' angles
        (:data:`ARM_PRIOR_COLUMNS`) from the body's rest angles."""
        rest = self.body.rest_angles[ARM_PRIOR_COLUMNS - 7]
        return ((np.asarray(h, float)[:, ARM_PRIOR_COLUMNS] - rest) ** 2).sum(axis=1)

    def penetration_cm(self, points: np.ndarray) -> np.ndarray:
        """(P,) cm: summed depth of the elbows and wrists inside the torso's core (see
        :data:`TORSO_RADIUS_SHARE`) for the body's named points (P, NPT, 3) m (numpy oracle of
        the kernel's E_P).

        Depth sees only the near side of a body and the detector's far-side joints are
        guesses, so nothing in E_D or E_J stops an occluded arm from sinking into the trunk
        (in a side view the far arm can settle well inside the torso); this term does."""
        pts = points[:, self._penetration_points]
        arms, hip, shoulder = pts[:, :4], pts[:, 4:6].mean(axis=1), pts[:, 6:8].mean(axis=1)
        axis = shoulder - hip
        along = np.einsum("pjk,pk->pj", arms - hip[:, None], axis) / np.maximum(np.einsum("pk,pk->p", axis, axis),
                                                                                 1e-12)[:, None]
        nearest = hip[:, None] + np.clip(along, 0.0, 1.0)[..., None] * axis[:, None]
        inside = np.maximum(self.torso_radius - np.linalg.norm(arms - nearest, axis=2), 0.0)
        return 100.0 * inside.sum(axis=1)

    def silhouette_cm(self, counts: dict[str, np.ndarray], normaliser: float) -> np.ndarray:
        """(P,) cm: E_S, T for each of the tile's rendered pixels that no observation within T
        confirms (``rendered - close``), divided like E_D by ``normaliser`` (the active level's N_P).

        E_D charges an observed pixel the model misses, not a model pixel over nothing or over a
        wall farther than T behind it (which costs T covered or not), so a body can grow for free;
        the shape fit adds this term, tracking leaves it off."""
        unconfirmed = (counts["rendered"] - counts["close"]).astype(float)
        return 100.0 * self.scorer.threshold * unconfirmed / normaliser

    @property
    def _swap_px(self) -> float:
        return SWAP_COST * max(self.targets.extent_px, 1.0)

    def _assignment(self, projected: np.ndarray) -> np.ndarray | None:
        """(P, n) model point index per target: each detected left/right pair matched straight or
        crossed, whichever fits the projected model points (P, n, 2) better (crossed: at a cost);
        None when no pair is detected or swaps are off."""
        pairs = self.targets.pairs
        if not self.weights.label_swaps or len(pairs) == 0:
            return None
        left, right = pairs[:, 0], pairs[:, 1]
        xy = self.targets.xy
        straight = (np.linalg.norm(projected[:, left] - xy[left], axis=2)
                    + np.linalg.norm(projected[:, right] - xy[right], axis=2))
        crossed = (np.linalg.norm(projected[:, right] - xy[left], axis=2)
                   + np.linalg.norm(projected[:, left] - xy[right], axis=2) + 2 * self._swap_px)
        swap = crossed < straight
        if not swap.any():
            return None
        order = np.repeat(np.arange(self.targets.count)[None], len(projected), axis=0)
        order[:, left] = np.where(swap, right, left)
        order[:, right] = np.where(swap, left, right)
        return order

    def host_terms(self, points: np.ndarray) -> dict[str, np.ndarray]:
        """E_J2D (px), E_J3D (mm) and E_P (cm), each (P,), of the named points (P, NPT, 3) m in
        numpy: the oracle of the terms the kernel computes (0 where a term does not apply)."""
        zeros = np.zeros(len(points))
        e_2d = e_3d = zeros
        if self.targets.count:
            pts = points[:, self.targets.point_index]
            z = np.maximum(pts[..., 2:3], 1e-3)  # a point behind the camera must not flip sides
            f = np.array([self.intrinsics.fx, self.intrinsics.fy])
            c = np.array([self.intrinsics.cx, self.intrinsics.cy])
            projected = pts[..., :2] / z * f + c
            order = self._assignment(projected)
            e_2d = weighted_joint_distance(projected, self.targets.xy, self.targets.weight, order, self._swap_px)
            e_3d = 1000.0 * weighted_joint_distance(pts, self.targets.xyz, self.targets.weight, order)
        return {"E_J2D": e_2d, "E_J3D": e_3d, "E_P": self.penetration_cm(points)}

    def __call__(self, h: np.ndarray) -> np.ndarray:
        """E (P,) of poses h (P, 36), from one launch of the active level's scorer."""
        t0 = time.perf_counter()
        scorer = self.coarse if self.coarse_active and self.coarse is not None else self.scorer
        self._upload_targets(scorer)
        result = scorer.evaluate(h, render=self.uses_depth, points=False)
        t1 = time.perf_counter()
        w = self.weights
        zeros = np.zeros(len(result.sums))
        normaliser = self.normaliser if scorer is self.scorer else self.coarse_normaliser
        e_d = 100.0 * result.sums / normaliser if self.uses_depth else zeros
        e_2d, e_3d = (result.terms["E_J2D"], result.terms["E_J3D"]) if self.uses_joints else (zeros, zeros)
        e_j = w.alpha * e_2d + (1.0 - w.alpha) * e_3d
        e_p = result.terms["E_P"] if w.penetration > 0 else zeros
        e_a = self.arm_prior_rad2(h) if w.arm_prior > 0 else zeros
        e_s = self.silhouette_cm(result.counts, normaliser) if w.silhouette > 0 and self.uses_depth else zeros
        total = (w.depth * e_d + w.joints * e_j + w.penetration * e_p + w.arm_prior * self.arm_prior_scale * e_a
                 + w.silhouette * e_s)
        self.last_parts = {"E": total, "E_D": e_d, "E_J": e_j, "E_J2D": e_2d, "E_J3D": e_3d, "E_P": e_p, "E_A": e_a}
        if w.silhouette > 0:  # the shape fit's; tracking's published parts stay as they are
            self.last_parts["E_S"] = e_s
        self.last_counts = result.counts
        spent = self.spent_s
        spent["score"] += t1 - t0
        spent["joints"] += time.perf_counter() - t1
        spent["calls"] += 1
        return total


def search_split(spent_s: dict[str, float], pso_ms: float) -> dict[str, float]:
    """Where a frame's search (``pso_ms``, ms) went, from :attr:`Objective.spent_s` (s):
    ``score`` (the launch: forward kinematics and every term on the device), ``joint_term``
    (combining the terms on the host) and ``pso_update`` (the swarm's own arithmetic and
    everything else), all ms."""
    parts = {"score": 1000 * spent_s["score"], "joint_term": 1000 * spent_s["joints"]}
    return {**parts, "pso_update": max(pso_ms - sum(parts.values()), 0.0)}
