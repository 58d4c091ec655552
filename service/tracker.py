"""The hybrid tracker: per frame, PSO over the 36-D pose of the paper's objective (§2.3–2.4).

Per frame (:meth:`Tracker.step`):

1. The detection's joints (score >= ``min_score``) are lifted to J^e on the depth.
2. **Start**. With a previous solution (state *tracking*), particles start around it in a
   region that contains J^e: translations within ±(4 cm + the distance to the root that
   J^e's torso implies) per axis, root rotation within ±0.15 rad, each limb's angles
   within ±(0.25 rad + the angle its detected joints moved, seen from the limb's pivot,
   up to 1.2 rad);
   the last 5 solutions and the J^e torso pose are injected as particles. Without one (the
   first frame, or after the track was lost: state *init*), the torso pose of J^e
   (:func:`swarmpose.init_pose.torso_pose`) with the body's rest angles starts a
   joints-only PSO over wide angle ranges (twice the generations), whose result is the
   centre of the normal search. No manual initialisation.
3. **Search**. PSO (canonical or perturbed) of ``E = w_D·E_D + w_J·E_J``; the perturbation
   redraws one limb's angles (arm, leg or trunk/head) within ±0.5 rad.
4. **State**. The fit is *lost* when the 2D joints are off by more than
   ``lost_joint_error`` of the person's size (weighted mean) or fewer than
   ``lost_depth_agreement`` of the model's rendered pixels agree with the depth within T;
   the next frame then starts from J^e again. Frames with no usable joints and no previous
   solution, or with neither joints nor depth, are *lost* with the reason.
5. **Confidence** per evaluation joint, in 0..1: the mean of a 2D agreement
   ``s·exp(−½(d/σ)²)`` (s = detection score, d = distance model–detection in px,
   σ = 4 % of the person's size; only where the layout detects the joint) and a depth
   agreement ``exp(−½(Δz/5 cm)²)`` (Δz = rendered model depth − observed depth at the
   joint's pixel, nearest common pixel within one tile pixel); 0 when neither exists.

Modes: ``hybrid`` (w_D = 3, w_J = 1), ``depth`` (w_J = 0; the joints only (re)initialise),
``joints`` (w_D = 0) and ``lift`` (J^e as the answer, no model).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from .camera import Intrinsics
from .errors import ConfigError, TrackingError
from .gpu.tile import box_around
from .init_pose import torso_pose
from .joints2d.base import Joints2D
from .kinematics import matrix_to_quaternion, quaternion_to_matrix
from .lift import lift_eval_joints
from .model.body import SkinnedBody
from .model.skeleton import (
    ANGLE_JOINT,
    ANGLE_LIMITS,
    ANGLES,
    EVAL_JOINTS,
    JOINT_INDEX,
    POSE_DIM,
    ROOT_QUATERNION,
)
from .objective import JointTargets, Objective, ObjectiveWeights
from .pso import PsoConfig, minimise
from .sources.base import Frame

MODES = ("hybrid", "depth", "joints", "lift")
MODE_WEIGHTS = {"hybrid": (3.0, 1.0), "depth": (1.0, 0.0), "joints": (0.0, 1.0)}
STATES = ("init", "tracking", "lost")

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

HISTORY = 5


@dataclass(frozen=True)
class TrackerConfig:
    """Everything that changes how a frame is tracked. ``depth_weight`` / ``joints_weight``
    None take the mode's values; ``smoothing`` in 0..1 (0 = off) blends each output pose
    with the previous one."""

    mode: str = "hybrid"
    pso: PsoConfig = field(default_factory=PsoConfig)
    depth_weight: float | None = None
    joints_weight: float | None = None
    alpha: float = 0.97
    threshold_m: float = 0.30
    min_score: float = 0.3
    tile: tuple[int, int] = (64, 64)
    triangles: int = 1500
    seed: int = 0
    smoothing: float = 0.0
    lost_joint_error: float = 0.12
    lost_depth_agreement: float = 0.4
    device: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"mode must be one of {MODES}, got {self.mode!r}")
        if not 0.0 <= self.smoothing < 1.0:
            raise ConfigError(f"smoothing must be within 0..1 (0 = off), got {self.smoothing}")

    @property
    def weights(self) -> ObjectiveWeights:
        w_d, w_j = MODE_WEIGHTS.get(self.mode, (0.0, 1.0))
        return ObjectiveWeights(depth=w_d if self.depth_weight is None else self.depth_weight,
                                joints=w_j if self.joints_weight is None else self.joints_weight,
                                alpha=self.alpha, threshold_m=self.threshold_m, min_score=self.min_score)


@dataclass(frozen=True)
class TrackResult:
    """One frame's answer.

    state: init | tracking | lost; reason: why (empty when tracking normally);
    pose: (36,) or None; joints3d: (14, 3) m camera frame in ``EVAL_JOINTS`` order (NaN
    where unknown); joints2d: (14, 2) px; confidence: (14,) 0..1; objective: E and its
    terms of the best particle; timings_ms: where the frame's time went.
    """

    index: int
    timestamp_ns: int
    state: str
    reason: str
    pose: np.ndarray | None
    joints3d: np.ndarray
    joints2d: np.ndarray
    confidence: np.ndarray
    objective: dict[str, float]
    timings_ms: dict[str, float]

    def joints_box(self) -> np.ndarray | None:
        """(4,) [u0, v0, u1, v1] px around the finite 2D joints (where to detect next), or None."""
        ok = np.all(np.isfinite(self.joints2d), axis=1)
        if not ok.any():
            return None
        pts = self.joints2d[ok]
        return np.concatenate([pts.min(axis=0), pts.max(axis=0)])

    def as_dict(self) -> dict:
        """JSON-ready: joints by name, numbers rounded to µm / 0.01 px."""
        vec = json_vector
        return {
            "frame": self.index, "timestamp_ns": self.timestamp_ns, "state": self.state, "reason": self.reason,
            "pose": None if self.pose is None else [round(float(x), 6) for x in self.pose],
            "joints3d": {j: vec(p, 6) for j, p in zip(EVAL_JOINTS, self.joints3d)},
            "joints2d": {j: vec(p, 2) for j, p in zip(EVAL_JOINTS, self.joints2d)},
            "confidence": {j: round(float(c), 3) for j, c in zip(EVAL_JOINTS, self.confidence)},
            "objective": {k: round(float(v), 4) for k, v in self.objective.items()},
            "timings_ms": {k: round(float(v), 2) for k, v in self.timings_ms.items()},
        }


def json_vector(v: np.ndarray, digits: int) -> list[float] | None:
    """A vector as a JSON list rounded to ``digits`` decimals, or None when any entry is not finite."""
    return [round(float(x), digits) for x in v] if np.all(np.isfinite(v)) else None


def _nan_joints(n: int = len(EVAL_JOINTS), k: int = 3) -> np.ndarray:
    return np.full((n, k), np.nan)


class Tracker:
    """Tracks one person in a stream of frames with a body model (see the module docstring)."""

    def __init__(self, body: SkinnedBody, intrinsics: Intrinsics, config: TrackerConfig = TrackerConfig()):
        self.config, self.intrinsics = config, intrinsics
        self.body = body if len(body.triangles) <= config.triangles else body.tracking_lod(config.triangles)
        self.weights = config.weights
        self.objective: Objective | None = None
        if config.mode != "lift":
            from .gpu.scorer import ParticleScorer

            scorer = ParticleScorer(self.body, intrinsics, config.tile, threshold=config.threshold_m,
                                    device=config.device)
            self.objective = Objective(self.body, intrinsics, scorer, self.weights)
        self.history: list[np.ndarray] = []
        self.previous: np.ndarray | None = None
        self.lo = np.full(POSE_DIM, -np.inf)
        self.hi = np.full(POSE_DIM, np.inf)
        self.lo[ROOT_QUATERNION], self.hi[ROOT_QUATERNION] = -1.0, 1.0
        self.lo[ANGLES], self.hi[ANGLES] = ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1]
        self._limb_columns = [7 + np.flatnonzero(np.isin(ANGLE_JOINT, [JOINT_INDEX[j] for j in group]))
                              for group in LIMB_GROUPS]

    # ------------------------------------------------------------------ helpers
    def reset(self) -> None:
        """Forget the track: the next frame initialises from its detection."""
        self.history.clear()
        self.previous = None

    @staticmethod
    def _renormalise(x: np.ndarray) -> np.ndarray:
        q = x[:, ROOT_QUATERNION]
        n = np.linalg.norm(q, axis=1, keepdims=True)
        x[:, ROOT_QUATERNION] = np.where(n > 1e-9, q / np.maximum(n, 1e-9), np.array([0.0, 1.0, 0.0, 0.0]))
        return x

    def _perturb(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        x = x.copy()
        for i in range(len(x)):
            cols = self._limb_columns[int(rng.integers(len(self._limb_columns)))]
            x[i, cols] += rng.uniform(-0.5, 0.5, len(cols))
        return x

    def _spread(self, centre: np.ndarray, count: int, rng: np.random.Generator, t_radius: np.ndarray,
                rot_radius: float, angle_radius) -> np.ndarray:
        """``count`` poses uniformly around ``centre`` (36,): translation ±t_radius (3,) m, root
        rotation ±rot_radius rad per axis, angles ±angle_radius rad (scalar or (29,); clipped
        to the limits)."""
        x = np.repeat(centre[None], count, axis=0)
        x[:, :3] += rng.uniform(-1.0, 1.0, (count, 3)) * t_radius
        turn = Rotation.from_rotvec(rng.uniform(-rot_radius, rot_radius, (count, 3))).as_matrix()
        rot = turn @ quaternion_to_matrix(centre[ROOT_QUATERNION])
        q = matrix_to_quaternion(rot)
        q *= np.sign(q @ centre[ROOT_QUATERNION] + 1e-12)[:, None]  # stay in the centre's hemisphere
        x[:, ROOT_QUATERNION] = q
        x[:, 7:] += rng.uniform(-angle_radius, angle_radius, (count, 29))
        x[:, 7:] = np.clip(x[:, 7:], ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
        return x

    def _angle_radius(self, centre: np.ndarray, targets: JointTargets) -> np.ndarray:
        """(29,) per-angle search half-width: each limb's widens with how far its detected
        joints moved from the previous solution's, as an angle seen from the limb's pivot
        (so the region holds the pose J^e implies)."""
        radius = np.full(29, ANGLE_RADIUS[0])
        if targets.count == 0:
            return radius
        names = tuple(dict.fromkeys([p for pivot, ends in LIMB_ENDS for p in (pivot, *ends)]))
        pts = dict(zip(names, self.body.posed_points(centre[None], names)[0]))
        detected = dict(zip(targets.names, targets.xy))
        for (pivot, ends), cols in zip(LIMB_ENDS, self._limb_columns):
            moved = []
            for end in ends:
                if end not in detected:
                    continue
                shift = np.linalg.norm(self.intrinsics.project(pts[end][None])[0] - detected[end])
                reach = np.linalg.norm(pts[end] - pts[pivot]) * self.intrinsics.fx / max(pts[end][2], 0.1)
                moved.append(shift / max(reach, 1.0))
            if moved:
                radius[cols - 7] = np.clip(ANGLE_RADIUS[0] + max(moved), *ANGLE_RADIUS)
        return radius

    def _box(self, reference: np.ndarray | None, targets: JointTargets) -> tuple[float, float, float, float]:
        pts = []
        if reference is not None:
            verts = self.body.pose(reference[None])[0]
            verts = verts[verts[:, 2] > 0.05]
            if len(verts):
                pts.append(self.intrinsics.project(verts))
        if targets.count:
            xy = targets.xy
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            grow = 0.2 * (hi - lo) + 10.0
            pts.append(np.array([lo - grow, hi + grow]))
        return box_around(np.concatenate(pts), margin=0.1)

    # ------------------------------------------------------------------ per frame
    def step(self, frame: Frame, joints: Joints2D | None) -> TrackResult:
        """Track one frame with its detection (None: no detector output for it)."""
        t0 = time.perf_counter()
        depth = np.asarray(frame.depth, dtype=np.float32)
        if depth.shape != (self.intrinsics.height, self.intrinsics.width):
            raise TrackingError(f"frame {frame.index}: depth is {depth.shape[1]}x{depth.shape[0]}, the tracker's "
                                f"camera is {self.intrinsics.width}x{self.intrinsics.height}; use one intrinsics "
                                "file for the whole sequence")
        depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(0.0))
        if self.config.mode == "lift":
            j3 = lift_eval_joints(depth, self.intrinsics, joints, self.config.min_score)
            j2 = self.intrinsics.project(np.where(np.isfinite(j3), j3, 1.0))
            j2[~np.all(np.isfinite(j3), axis=1)] = np.nan
            ok = np.all(np.isfinite(j3), axis=1)
            state, reason = ("tracking", "") if ok.any() else ("lost", "no joints detected with depth")
            return TrackResult(frame.index, frame.timestamp_ns, state, reason, None, j3, j2, ok.astype(float), {},
                               {"total": 1000 * (time.perf_counter() - t0)})
        targets = JointTargets.from_detection(joints, depth, self.intrinsics, self.body, self.config.min_score)
        has_depth = bool(np.any(depth > 0))
        lifted = {n: p for n, p in zip(targets.names, targets.xyz)}
        state = "tracking" if self.previous is not None else "init"
        if self.previous is None:
            centre = torso_pose(self.body, lifted, self.body.rest_angles)
            if centre is None:
                why = "no person: fewer than 3 of the hips and shoulders detected with depth"
                return self._empty(frame, why, t0)
        if not has_depth and targets.count == 0:
            return self._empty(frame, "no joints detected and no valid depth", t0)

        rng = np.random.default_rng([self.config.seed, frame.index])
        pso = self.config.pso
        timings: dict[str, float] = {}
        if state == "init":
            centre = self._initialise(centre, targets, rng, timings)
            seeds = [centre]
            start = self._spread(centre, pso.particles, rng, np.full(3, 0.04), 0.1, 0.15)
        else:
            centre = self.previous
            torso = torso_pose(self.body, lifted, centre[7:])
            offset = np.abs(torso[:3] - centre[:3]) if torso is not None else np.zeros(3)
            start = self._spread(centre, pso.particles, rng, 0.04 + offset, 0.15, self._angle_radius(centre, targets))
            seeds = [centre] + self.history[-HISTORY:][::-1] + ([torso] if torso is not None else [])
        for i, s in enumerate(seeds[:pso.particles]):
            start[i] = s

        t1 = time.perf_counter()
        box = self._box(centre, targets)
        self.objective.set_frame(depth, box, targets, centre)
        result = minimise(self.objective, start, self.lo, self.hi, rng, pso, self._renormalise, self._perturb)
        timings["pso"] = 1000 * (time.perf_counter() - t1)
        best = result.best
        parts = {k: float(v[0]) for k, v in self._parts(best).items()}
        if self.config.smoothing > 0 and self.previous is not None and state == "tracking":
            best = self._smooth(best)
        tile, counts = self._render(best)
        out_state, reason = self._judge(counts, targets, parts, state)
        if out_state == "lost":
            self.reset()
        else:
            self.previous = best
            self.history.append(best)
            del self.history[:-HISTORY]
        joints3d = self.body.posed_points(best[None], EVAL_JOINTS)[0]
        joints2d = self.intrinsics.project(joints3d)
        confidence = self._confidence(tile, joints2d, joints, targets)
        timings["total"] = 1000 * (time.perf_counter() - t0)
        return TrackResult(frame.index, frame.timestamp_ns, out_state, reason, best, joints3d, joints2d, confidence,
                           parts, timings)

    def _empty(self, frame: Frame, reason: str, t0: float) -> TrackResult:
        self.reset()
        return TrackResult(frame.index, frame.timestamp_ns, "lost", reason, None, _nan_joints(), _nan_joints(k=2),
                           np.zeros(len(EVAL_JOINTS)), {}, {"total": 1000 * (time.perf_counter() - t0)})

    def _initialise(self, centre: np.ndarray, targets: JointTargets, rng: np.random.Generator,
                    timings: dict[str, float]) -> np.ndarray:
        """Joints-only PSO over wide angle ranges from the J^e torso pose; returns the centre for the frame."""
        if targets.count == 0:
            return centre
        t = time.perf_counter()
        joints_only = Objective(self.body, self.intrinsics, self.objective.scorer,
                                replace(self.weights, depth=0.0, joints=1.0))
        joints_only.targets = targets
        pso = replace(self.config.pso, generations=2 * self.config.pso.generations, variant="perturbed")
        start = self._spread(centre, pso.particles, rng, np.full(3, 0.08), 0.3, 1.0)
        start[0] = centre
        result = minimise(joints_only, start, self.lo, self.hi, rng, pso, self._renormalise, self._perturb)
        timings["init"] = 1000 * (time.perf_counter() - t)
        return result.best

    def _parts(self, h: np.ndarray) -> dict[str, np.ndarray]:
        self.objective(h[None])
        return self.objective.last_parts

    def _smooth(self, best: np.ndarray) -> np.ndarray:
        a = self.config.smoothing
        out = (1 - a) * best + a * self.previous
        out[ROOT_QUATERNION] /= np.linalg.norm(out[ROOT_QUATERNION])
        return out

    def _render(self, best: np.ndarray) -> tuple[np.ndarray | None, dict[str, np.ndarray] | None]:
        """The best pose's depth tile (TH, TW) m and its counts, once per frame; (None, None)
        when the frame's box holds no observed depth."""
        observed = self.objective.scorer.observed
        if observed is None or not np.any(observed > 0):
            return None, None
        tiles, _, counts = self.objective.scorer.render_and_score(best[None])
        return tiles[0], counts

    def _judge(self, counts: dict[str, np.ndarray] | None, targets: JointTargets, parts: dict[str, float],
               state: str) -> tuple[str, str]:
        obj = self.objective
        if obj.uses_joints:
            size = targets.extent_px
            if size > 0 and parts["E_J2D"] > self.config.lost_joint_error * size:
                return "lost", f"2D joints off by {parts['E_J2D']:.0f} px (person {size:.0f} px)"
        if counts is not None and obj.weights.depth > 0:
            rendered = int(counts["rendered"][0])
            agree = int(counts["close"][0]) / rendered if rendered else 0.0
            if agree < self.config.lost_depth_agreement:
                return "lost", f"only {100 * agree:.0f} % of the model's pixels agree with the depth"
        if not obj.uses_joints and not obj.has_depth:
            return "lost", "no joints and no depth to fit"
        return state, "" if obj.uses_joints else "no joints detected: depth only"

    def _confidence(self, tile: np.ndarray | None, joints2d: np.ndarray, joints: Joints2D | None,
                    targets: JointTargets) -> np.ndarray:
        scores = np.full((len(EVAL_JOINTS), 2), np.nan)
        detected = joints.by_point(self.config.min_score) if joints is not None else {}
        sigma = max(0.04 * targets.extent_px, 4.0)
        for i, name in enumerate(EVAL_JOINTS):
            if name in detected:
                x, y, s = detected[name]
                d = float(np.hypot(joints2d[i, 0] - x, joints2d[i, 1] - y))
                scores[i, 0] = s * np.exp(-0.5 * (d / sigma) ** 2)
        tb, observed = self.objective.scorer.tile_box, self.objective.scorer.observed
        if tile is not None:
            tu = np.floor((joints2d[:, 0] - tb.u0 + 0.5) / tb.bw * tb.tw).astype(int)
            tv = np.floor((joints2d[:, 1] - tb.v0 + 0.5) / tb.bh * tb.th).astype(int)
            for i in range(len(EVAL_JOINTS)):
                if not (0 <= tu[i] < tb.tw and 0 <= tv[i] < tb.th):
                    continue
                r = tile[max(tv[i] - 1, 0):tv[i] + 2, max(tu[i] - 1, 0):tu[i] + 2]
                o = observed[max(tv[i] - 1, 0):tv[i] + 2, max(tu[i] - 1, 0):tu[i] + 2]
                both = (r > 0) & (o > 0)
                if both.any():
                    dz = float(np.min(np.abs(r[both] - o[both])))
                    scores[i, 1] = np.exp(-0.5 * (dz / 0.05) ** 2)
        known = np.isfinite(scores)
        return np.where(known, scores, 0.0).sum(axis=1) / np.maximum(known.sum(axis=1), 1)
