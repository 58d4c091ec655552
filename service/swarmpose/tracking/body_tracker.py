"""The hybrid tracker of one body: per frame, PSO over the 36-D pose of the paper's objective (§2.3–2.4).

Per frame (:meth:`BodyTracker.step`):

1. The detection's joints (score >= ``min_score``) are lifted to J^e on the depth. With a
   previous solution, the lifts of limb joints it hides behind its own body, where the depth
   shows that occluder, leave the 3D term (:mod:`swarmpose.tracking.hidden_lifts`, ``hidden_lifts``).
2. **Start**. With a previous solution (state *tracking*), particles start around it in a
   region that contains J^e (:mod:`swarmpose.tracking.search`); the last 5 solutions and
   the J^e torso pose are injected as particles, and so are the previous solution's limbs
   mirrored along the line of sight and, side on, its left and right legs, and arms, exchanged
   (:mod:`swarmpose.tracking.limb_flips`, ``limb_flips``; :mod:`swarmpose.tracking.limb_exchanges`, ``limb_exchanges``),
   and its arms sent to depth within reach that its body does not explain and to each other's
   mirror image (:mod:`swarmpose.tracking.arm_proposals`, ``arm_proposals``); searched by the
   whole-pose swarm, the best ``hypotheses`` of these flips and proposals each with a sub-swarm that
   refines it apart from the track for most of the generations (:mod:`swarmpose.tracking.hypotheses`); every
   ``recheck`` frames the start's facings, refitted from the detection, compete as particles
   too. Without one (the first frame, or after the track was lost: state *init*), the torso
   pose of J^e (:func:`swarmpose.tracking.init_pose.torso_pose`) with the body's rest angles,
   turned to each of four facings (side and back views make its facing unreliable), starts one
   PSO over wide angle ranges each; the best fit by the objective is the centre of the normal
   search, the others join it as particles. No manual initialisation.
3. **Search**. PSO of ``E = w_D·E_D + w_J·E_J``: with ``search`` swarm (and auto offline) the
   paper's (canonical or perturbed) of the whole pose, with the hypotheses' sub-swarms; with
   ``search`` blocks (and auto with a frame budget, live) the whole-pose swarm without sub-swarms
   for a quarter of the generations, then block by block, each particle moving the root, the
   trunk or one limb of a pose the swarm shares, each flip and proposal (none on a lean live
   frame) starting a particle of its limb's sub-swarm (:mod:`swarmpose.tracking.block_pso`). A
   start, and a frame whose seeds hold another facing (re-checked facings, a challenger), search
   with the whole-pose swarm: a turned pose must be refined whole to compete with the track, which
   blocks of it cannot do. With ``polish``, a local
   search takes the chosen pose (young track: each facing's best) further down E, arms as searched (.pose_polish).
4. **Verdict** (:mod:`swarmpose.tracking.verdict`): lost or not, and per-joint confidence.
   Frames with no usable joints and no previous solution, or with neither joints nor
   depth, are *lost* with the reason; the next frame then starts from J^e again.

Modes: ``hybrid`` (w_D = 3, w_J = 1), ``depth`` (w_J = 0; the joints only (re)initialise),
``joints`` (w_D = 0) and ``lift`` (J^e as the answer, no model).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from swarmpose.body.kinematics import root_turn_deg
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import TrackingError
from swarmpose.core.timing import timed
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around
from swarmpose.sources.base import Frame
from swarmpose.tracking import search, verdict
from swarmpose.tracking.arm_proposals import arm_proposals
from swarmpose.tracking.block_pso import BLOCKS, changed_block, whole_then_blocks
from swarmpose.tracking.body_scene import body_scene
from swarmpose.tracking.budget import POLISH_CANDIDATES, FrameBudget, lean_frame
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.facings import YOUNG_RECHECKS, fit_facings, recheck_facings
from swarmpose.tracking.fitting import BodyFitting
from swarmpose.tracking.hidden_lifts import without_hidden_lifts
from swarmpose.tracking.history import TrackHistory
from swarmpose.tracking.hypotheses import MERGE_SHARE, hypothesis_groups
from swarmpose.tracking.init_pose import NO_TORSO, torso_pose
from swarmpose.tracking.lift import lifted_body
from swarmpose.tracking.lifted_limbs import lifted_limb_seeds
from swarmpose.tracking.limb_exchanges import limb_exchanges
from swarmpose.tracking.limb_flips import limb_flips
from swarmpose.tracking.objective import JointTargets, Objective, search_split
from swarmpose.tracking.one_euro import PoseFilter
from swarmpose.tracking.pose_polish import polish_solution
from swarmpose.tracking.pso import PsoConfig, PsoResult, minimise
from swarmpose.tracking.result import BodyResult, lost_body, posed_skeleton

REPLACED_TURN_DEG = 90.0
"""A frame's solution turned this far (root rotation, degrees) from the last frame's is a
challenger to the track (a re-check's or the start's other facing won): no body turns that far
in one frame. It replaces the track only when it wins two frames running (the frame between
publishes the best solution of the track's own facing), and then the old track's poses are
dropped from the history (:mod:`swarmpose.tracking.history`). One frame's detection that swapped sides (people seen from
behind) flipped tracks either way: kept as seeds, the old poses won back a mirrored facing;
accepted at once, a mirrored re-check replaced a right track."""


def observed_depth(depth: np.ndarray) -> np.ndarray:
    """Depth (H, W) as float32 m, every invalid reading (NaN, inf, <= 0) set to 0 (no measurement)."""
    depth = np.asarray(depth, dtype=np.float32)
    return np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(0.0))


class BodyTracker:
    """Tracks one person in a stream of frames with a body model (see the module docstring).

    body: the (personalised) body; decimated to ``config.triangles`` for tracking.
    intrinsics: the camera of every frame. context: the OpenCL device to score on (None:
    the one ``config.device`` names).
    """

    def __init__(self, body: SkinnedBody, intrinsics: Intrinsics, config: TrackerConfig | None = None,
                 context: ClContext | None = None, body_id: int = 0, fitting: BodyFitting | None = None):
        config = config or TrackerConfig()
        self.config, self.intrinsics, self.body_id = config, intrinsics, body_id
        self.body = body if len(body.triangles) <= config.triangles else body.tracking_lod(config.triangles)
        self.weights = config.weights
        self.objective: Objective | None = None
        if config.mode != "lift":
            context = context or ClContext.for_spec(config.device)
            scorer = ParticleScorer(self.body, intrinsics, config.tile, threshold=config.threshold_m, context=context)
            self.objective = Objective(self.body, intrinsics, scorer, self.weights, self._coarse_scorer(context))
        self.history = TrackHistory()
        self.previous: np.ndarray | None = None
        self.age = 0  # frames tracked since the track's start (0 on the start's frame)
        self.challenger: np.ndarray | None = None
        """Last frame's winning solution turned away from the track (see :data:`REPLACED_TURN_DEG`)."""
        self.best_counts: dict[str, np.ndarray] | None = None  # the last frame's, see _render
        self.on_step = None  # called with (self, frame, joints, others_removed) first (the offline backward pass)
        self.filter = (PoseFilter(config.smoothing_cutoff_hz, config.smoothing_beta)
                       if config.smoothing == "one-euro" else None)
        """The published poses' filter (``--smoothing one-euro``); the search never sees its output."""
        self.lo, self.hi = search.pose_bounds()
        self.frame_period_s: float | None = None  # the camera's (s): dropped frames widen the search (None: none)
        self.budget_ms = 0.0  # the time a frame may take (ms, live: tracking.budget); 0: the configured search
        self.costs = FrameBudget()
        self.fitting = fitting
        """What fits the body to the person as they are tracked (None: the body as given)."""
        if fitting is not None:
            fitting.attach(self)

    @property
    def device_name(self) -> str:
        """``platform: device`` of the OpenCL device scoring, or "" (lift mode)."""
        return "" if self.objective is None else self.objective.scorer.cl_context.name

    def set_body(self, body: SkinnedBody) -> None:
        """Track with ``body`` from now on: another shape of this tracker's body with the same
        tracking topology (a :class:`~swarmpose.body.shape_space.ShapeSpace`'s tracking body).
        The track goes on from the last pose."""
        if self.objective is not None:  # first: a body the scorer refuses leaves the tracker as it was
            self.objective.set_body(body)
        self.body = body
        if self.objective is not None and self.objective.coarse is not None:
            self.objective.coarse = self._coarse_scorer(self.objective.scorer.cl_context)

    def _coarse_scorer(self, context: ClContext) -> ParticleScorer | None:
        """The coarse level's scorer of :attr:`body` (coarse-to-fine search), None when it is off."""
        config = self.config
        if config.coarse_share <= 0:
            return None
        coarse_body = (self.body if len(self.body.triangles) <= config.coarse_triangles
                       else self.body.tracking_lod(config.coarse_triangles))
        return ParticleScorer(coarse_body, self.intrinsics, config.coarse_tile, threshold=config.threshold_m,
                              context=context)

    def personalisation(self) -> dict | None:
        """The state of the body's fitting to the person (:attr:`fitting`); None: none."""
        return None if self.fitting is None else self.fitting.personalisation(self)

    def new_person(self) -> None:
        """Track another person from the next frame (a tracker reused for a new id)."""
        self.reset()
        if self.fitting is not None:
            self.fitting.new_person(self)

    def reset(self) -> None:
        """Forget the track: the next frame initialises from its detection."""
        self.history.clear()
        self.previous, self.age, self.challenger = None, 0, None
        if self.filter is not None:
            self.filter.reset()

    def search_box(self, reference: np.ndarray | None, targets: JointTargets) -> tuple[float, float, float, float]:
        """The box B (u0, v0, width, height) px the depth term looks in: around the silhouette of
        the ``reference`` pose (36,) (None: none) and the detected joints, grown 10 %."""
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

    def step(self, frame: Frame, joints: Joints2D | None, others_removed: bool = False,
             start_min_score: float | None = None) -> BodyResult:
        """Track one frame with its detection (None: no detector output for it). others_removed:
        other people's pixels were taken out of ``frame.depth`` (several people), so the lost
        test's depth agreement counts only the model's pixels that have an observation.
        start_min_score: the least keypoint score at a track's start (None: ``config.min_score``).

        Three steps: the input kept for the offline backward pass (:attr:`on_step`), the frame's
        fit (:meth:`fit_frame`), and the body's fitting to the person from its result (:attr:`fitting`)."""
        if self.on_step is not None:
            self.on_step(self, frame, joints, others_removed)
        result = self.fit_frame(frame, joints, others_removed, start_min_score)
        if self.fitting is not None:
            self.fitting.after_frame(self, frame, joints, others_removed, result)
        return result

    def fit_frame(self, frame: Frame, joints: Joints2D | None, others_removed: bool = False,
                  start_min_score: float | None = None) -> BodyResult:
        """The pose of one frame (see the module docstring and :meth:`step` for the arguments)."""
        t0 = time.perf_counter()
        depth = np.asarray(frame.depth, dtype=np.float32)
        if depth.shape != (self.intrinsics.height, self.intrinsics.width):
            raise TrackingError(f"frame {frame.index}: depth is {depth.shape[1]}x{depth.shape[0]}, the tracker's "
                                f"camera is {self.intrinsics.width}x{self.intrinsics.height}; use one intrinsics "
                                "file for the whole sequence")
        depth = observed_depth(depth)
        if self.config.mode == "lift":
            return lifted_body(self.body_id, depth, self.intrinsics, joints, self.config.min_score, t0)
        least = start_min_score if self.previous is None and start_min_score is not None else self.config.min_score
        targets = JointTargets.from_detection(joints, depth, self.intrinsics, self.body, least)
        has_depth = bool(np.any(depth > 0))
        lifted = {n: p for n, p in zip(targets.names, targets.xyz)}
        state = "tracking" if self.previous is not None else "init"
        if self.previous is None:
            centre = torso_pose(self.body, lifted, self.body.rest_angles)
            if centre is None:
                return self._lost(NO_TORSO, t0, joints)
        if not has_depth and targets.count == 0:
            return self._lost("no joints detected and no valid depth", t0, joints)

        rng = np.random.default_rng([self.config.seed, frame.index])
        pso, rounds = self.costs.sized(self.budget_ms, self.config.pso_config, self.config.polish,  # live: sized
                                       start=state == "init")
        timings: dict[str, float] = {}
        proposals: list[np.ndarray] = []  # limb flips and arm proposals (tracking only)
        contested = False  # another facing (a re-check's, a challenger) competes with the track
        if state == "init":
            seeds = fit_facings(self, centre, targets, depth, rng, timings)
            centre = seeds[0]
            box = self.search_box(centre, targets)
            start = search.spread(centre, pso.particles, rng, np.full(3, 0.04), 0.1, 0.15)
        else:  # the track's last pose, its motion, the re-checked facings and the proposals
            centre = self.previous
            targets, start, seeds, proposals, box, radius, contested = self._tracking_start(
                frame, lifted, targets, depth, rng, timings, pso)
        for i, s in enumerate((seeds + proposals)[:pso.particles]):
            start[i] = s
        t1 = time.perf_counter()
        self.objective.set_frame(depth, box, targets, centre)
        blocks = (state == "tracking" and not contested and self.searches_by_blocks()
                  and pso.particles > len(BLOCKS))  # the shared pose and a particle a block at least
        groups = None
        if state == "tracking" and not blocks:  # the ranking's time is its own, not the search's
            with timed(timings, "hypotheses"):
                groups = hypothesis_groups(self.objective, proposals, start, self.config.hypotheses, radius, rng,
                                           keep=len(seeds))
        self.objective.take_spent()
        result = self.pso_search(self.objective, start, rng, pso, groups, blocks, proposals)
        timings["pso"] = 1000 * (time.perf_counter() - t1) - timings.get("hypotheses", 0.0)
        timings.update(search_split(self.objective.take_spent(), timings["pso"]))
        duel = self.age < max(YOUNG_RECHECKS) and self.previous is not None  # a young track: both facings polished
        with timed(timings, "polish"):  # polish 0: as it is
            best = polish_solution(self.objective, result, self.previous, rounds, rng, duel,
                                   self._hold_facing, REPLACED_TURN_DEG)
        scored = result.evaluations + POLISH_CANDIDATES * rounds * (1 + duel)  # the swarm's and the polish's
        return self._judge(frame, joints, targets, state, best, scored, others_removed, timings, t0)

    def _judge(self, frame: Frame, joints: Joints2D | None, targets: JointTargets, state: str, best: np.ndarray,
               scored: int, others_removed: bool, timings: dict[str, float], t0: float) -> BodyResult:
        """The frame's verdict on ``best`` (36,): lost or not, the track's state after it, the joints and
        their confidence, the cost model fed (``scored`` poses in the search and polish), the published result."""
        t_verdict = time.perf_counter()
        self.objective(best[None])
        parts = {k: float(v[0]) for k, v in self.objective.last_parts.items()}
        tile, counts = self._render(best)
        out_state, reason = verdict.judge(self.objective, counts, targets, parts, state,
                                          self.config.lost_joint_error, self.config.lost_depth_agreement,
                                          observed_only=others_removed)
        if out_state == "lost":
            self.reset()
        else:
            self.age = 0 if self.previous is None else self.age + 1
            self.previous = best
            self.history.add(best, frame.timestamp_ns)
        transforms = self.body.transforms(best[None])  # the joints' and the full set's (one forward kinematics)
        joints3d = self.body.points_at(transforms, EVAL_JOINTS)[0]
        joints2d = self.intrinsics.project(joints3d)
        conf = verdict.confidence(self.objective, tile, joints2d, joints, targets, self.config.min_score)
        timings["verdict"] = 1000 * (time.perf_counter() - t_verdict)
        timings["total"] = 1000 * (time.perf_counter() - t0)
        if state == "tracking":
            self.costs.record(timings["pso"] + timings["polish"], scored, timings["total"])
        out = BodyResult(self.body_id, out_state, reason, best, joints3d, joints2d, conf, parts, timings, joints,
                         skeleton=posed_skeleton(self.body, best, self.intrinsics, transforms))
        if self.filter is None or out_state == "lost":
            return out
        return self._filtered(out, frame.timestamp_ns * 1e-9)

    def _tracking_start(self, frame: Frame, lifted: dict[str, np.ndarray], targets: JointTargets, depth: np.ndarray,
                        rng: np.random.Generator, timings: dict[str, float], pso: PsoConfig) -> tuple:
        """A tracked frame's swarm start around the last pose: (targets less the lifts the body hides,
        start (P, 36), seeds, proposals, box, angle radius, whether another facing competes: the
        re-checked facings or a challenger are among the seeds). Seeds: the last pose, where its motion
        leads, the challenger, the history, the J^e torso and the re-checked facings; proposals: arms
        sent to unexplained depth and limbs mirrored in depth, as many as the swarm has room for."""
        centre = self.previous
        proposals: list[np.ndarray] = []
        hidden = self.config.hidden_lifts and self.config.mode != "depth"  # depth mode: no joint term
        lean = lean_frame(self.budget_ms, pso.generations)  # live, a starved search: no proposals
        arms = self.config.arm_proposals and self.config.mode != "joints" and not lean  # the depth judges them
        with timed(timings, "scene"):
            scene = body_scene(self.body, centre) if hidden or arms else None  # one posed body for both
        if hidden:
            with timed(timings, "hidden"):
                targets = without_hidden_lifts(self.body, centre, targets, self.intrinsics, scene)
        refit = pso.generations if self.budget_ms > 0 else max(pso.generations, self.config.start_budget)
        recheck = recheck_facings(self, frame.index, lifted, targets, depth, rng, timings, refit)  # the start's facings
        torso = torso_pose(self.body, lifted, centre[7:], upright=False)
        offset = np.abs(torso[:3] - centre[:3]) if torso is not None else np.zeros(3)
        radius = search.angle_radius(self.body, self.intrinsics, centre, targets)
        ahead = self.history.periods_since(frame.timestamp_ns, self.frame_period_s)  # > 1: frames dropped
        start = search.spread(centre, pso.particles, rng, 0.04 * np.sqrt(ahead) + offset, 0.15, radius)
        predicted = self.history.predicted(frame.timestamp_ns, ahead, every_step=self.budget_ms > 0)
        seeds = ([centre] + predicted + ([self.challenger] if self.challenger is not None else [])
                 + self.history.newest_first() + ([torso] if torso is not None else []) + recheck)
        if lean and self.config.mode != "depth":  # live, a short search: the limbs sent to their lifts
            with timed(timings, "lifted"):
                seeds += lifted_limb_seeds(self.body, [centre if torso is None else torso] + predicted[:1], targets)
        box = self.search_box(centre, targets)
        room = pso.particles - len(seeds)
        if arms and room > 0:  # as many as the swarm has room for
            with timed(timings, "arms"):
                proposals += arm_proposals(self.body, centre, depth, self.intrinsics, box, scene)[:room]
            room = pso.particles - len(seeds) - len(proposals)
        if self.config.limb_exchanges and room > 0 and not lean:
            with timed(timings, "flips"):
                proposals += limb_exchanges(self.body, centre)[:room]
            room = pso.particles - len(seeds) - len(proposals)
        if self.config.limb_flips and room > 0 and not lean:
            with timed(timings, "flips"):
                proposals += limb_flips(self.body, centre, most=room)
        return targets, start, seeds, proposals, box, radius, bool(recheck) or self.challenger is not None

    def _hold_facing(self, result: PsoResult) -> np.ndarray:
        """The frame's solution from the search's ``result``: its best, unless that is turned
        away from the track (:data:`REPLACED_TURN_DEG`) for the first frame running; then the
        best particle of the track's own facing, and the best is kept as the challenger that
        joins the next frame's swarm. A challenger that wins again (a best facing as it did)
        replaces the track; another turned best becomes the challenger instead."""
        best = result.best
        if root_turn_deg(self.previous, best) <= REPLACED_TURN_DEG:
            self.challenger = None
            return best
        again = self.challenger is not None and root_turn_deg(self.challenger, best) <= REPLACED_TURN_DEG
        own = result.best_among(root_turn_deg(self.previous, result.personal_bests) <= REPLACED_TURN_DEG)
        if again or own is None:  # the same challenger won twice (or nothing is left of the track)
            self.challenger = None
            self.history.clear()  # the old track's poses are no seeds for the new one
            if self.filter is not None:  # nor are they to be smoothed into the new one
                self.filter.reset()
            return best
        self.challenger = best
        return result.personal_bests[own].copy()

    def _filtered(self, result: BodyResult, time_s: float) -> BodyResult:
        """``result`` with its pose through :attr:`filter` and the joints of that pose; the search's own
        result stays in ``unfiltered`` (the next frame's start, the detector's box, association)."""
        pose = self.filter(result.pose, time_s)
        transforms = self.body.transforms(pose[None])
        joints3d = self.body.points_at(transforms, EVAL_JOINTS)[0]
        return replace(result, pose=pose, joints3d=joints3d, joints2d=self.intrinsics.project(joints3d),
                       unfiltered=result, skeleton=posed_skeleton(self.body, pose, self.intrinsics, transforms))

    def _lost(self, reason: str, t0: float, joints: Joints2D | None = None) -> BodyResult:
        self.reset()
        return lost_body(reason, self.body_id, {"total": 1000 * (time.perf_counter() - t0)}, joints)

    def searches_by_blocks(self) -> bool:
        """Whether a tracked frame searches block by block: ``search`` blocks, or auto with a frame budget;
        offline not while the track turns faster than ``turning_swarm`` deg/s (see there)."""
        blocks = self.config.search == "blocks" or (self.config.search == "auto" and self.budget_ms > 0)
        if not blocks or self.budget_ms > 0 or self.config.turning_swarm <= 0:
            return blocks
        rate = self.history.turn_rate_deg_s()
        return rate is None or rate <= self.config.turning_swarm

    def pso_search(self, objective: Objective, start: np.ndarray, rng: np.random.Generator, pso: PsoConfig,
                   groups: np.ndarray | None = None, blocks: bool = False,
                   proposals: Sequence[np.ndarray] = ()) -> PsoResult:
        """One PSO of ``objective`` from ``start`` (P, 36): coarse to fine when the objective
        renders and has a coarse level (the first ``config.coarse_share`` of the generations on
        it), else at full resolution throughout; ``groups``: sub-swarms (:mod:`swarmpose.tracking.hypotheses`).
        blocks: block by block (:mod:`swarmpose.tracking.block_pso`), at full resolution, without
        sub-swarms, each of ``proposals`` (whole poses, the previous pose with one limb changed)
        starting a particle of its limb's sub-swarm."""
        if blocks:
            changed = [(changed_block(p, self.previous), p) for p in proposals]
            return whole_then_blocks(objective, start, self.lo, self.hi, rng, pso, search.renormalise, search.perturb,
                                     [(b, p) for b, p in changed if b is not None])
        coarse = objective.uses_depth and objective.coarse is not None
        refine_at = self.config.refine_at(pso.generations) if coarse else 0
        objective.coarse_active = refine_at > 0
        try:
            return minimise(objective, start, self.lo, self.hi, rng, pso, search.renormalise, search.perturb,
                            refine_at=refine_at, refine=objective.use_full_resolution, groups=groups,
                            merge_at=int(MERGE_SHARE * pso.generations))
        finally:
            objective.coarse_active = False

    def _render(self, best: np.ndarray) -> tuple[np.ndarray | None, dict[str, np.ndarray] | None]:
        """The best pose's depth tile (TH, TW) m and its counts, once per frame, the counts kept as
        ``best_counts``; (None, None) when the frame's box holds no observed depth."""
        observed, self.best_counts = self.objective.scorer.observed, None
        if observed is None or not np.any(observed > 0):
            return None, None
        tiles, _, self.best_counts = self.objective.scorer.render_and_score(best[None])
        return tiles[0], self.best_counts
