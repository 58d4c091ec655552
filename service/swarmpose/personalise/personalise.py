"""Personalisation: the body's shape estimated from the depth and 2D joints of ordinary motion.

Input: samples of one person (a frame, its detection and the pose the tracker found with the
shape space's start body). :func:`fit_shape` chooses ``keyframes`` well-spread frames, then:

0. **Sweep.** A coarse grid (:data:`~swarmpose.personalise.fit_settings.SWEEP`: gender × height) of
   shapes, each with its own pose step, picks the start: poses tracked with the start body favour
   shapes like it. Its heights
   are fixed, so E_H favours the candidate nearest the measured stature whatever its build.
1. **Shape step.** A PSO over the space's parameters (:class:`~swarmpose.body.shape_space.ShapeSpace`)
   with the poses held, minimising the mean over the key frames of ``E + w_D·E_S`` (the
   tracker's objective E with its own weights, penetration term included, plus the silhouette
   term E_S below), plus ``w_B·E_B``, the bone-length term below, plus E_H, the stature term
   (:mod:`~swarmpose.personalise.shape_stature`: the height measured on the depth bounds the body's,
   which E barely tells apart). Each frame's root may move by
   one of :data:`ROOT_OFFSETS_M` per candidate (a taller body moves its hips). Each candidate
   shape is a buffer upload into one scorer per key frame (same topology), each scorer keeping
   its frame's observation for the whole fit.
2. **Pose step.** Every key frame's pose is refitted with the new shape by the tracker's own
   per-frame search (``pose_steps`` times), started from the frame's last pose, without the
   depth flips of the limbs (:mod:`~swarmpose.tracking.limb_flips`): a local refinement. Steps 1
   and 2 alternate for ``rounds`` rounds.
3. **Own poses.** A compass search over the parameters judges each candidate shape with every key
   frame's pose polished for it (:mod:`~swarmpose.personalise.own_pose_search`).

E_S, the silhouette term: the depth term charges an observed pixel the model misses (T) but not a
model pixel where nothing is seen, or where the sensor sees farther than T behind the model: a
wall behind the person costs T whether the model covers it or not. So a body could grow for free.
E_S charges T
for every rendered pixel of the tile that no observation within T confirms (rendered less
``close``, normalised like E_D, cm; :meth:`~swarmpose.tracking.objective.Objective.silhouette_cm`,
on at w_S = w_D). Its limit: an object in front of the person (closer than T)
is charged too, so fit from a recording where the person is in full view. The fit's frames have
their edge dropouts filled first (:func:`~swarmpose.personalise.depth_dropouts.fill_dropouts`),
which E_S would otherwise charge as empty space and shrink the body by (the observed bone lengths
are lifted on the filled depth too; the pose step, the stature measure and the online collection's
hidden share still read the frames as they are).

E_B, the bone-length term: the poses held during a shape step were fitted with the previous
shape, and a body too short can bend and lean to explain them. The distance between two
lifted joints of one limb does not depend on the pose, so E_B compares each limb's observed
length over all samples with the candidate's rest length (mean difference, cm). Noise on the
lifted joints only lengthens a distance on average (the part across the bone adds its square),
so the observed length is the median less that excess, estimated from the spread over frames
(:func:`debiased_length`). The lift itself misplaces joints too, by amounts that depend on the
body (a keypoint's depth is the nearest surface's, pushed back by a constant per joint). So
before the sweep and each round the
lift is run on the current shape's own noise-free render at the key frames' poses
(:func:`~swarmpose.personalise.lift_bias.lift_bias`), and E_B's lengths are the observed ones less
that bias: like E, E_B then compares what the sensor and the lift make of a body with what they
made of the person. The bias is each sweep candidate's own (its genders are far apart, and the
bias flips sign between male and female bodies), then in each round the current shape's, used
for every candidate of that round's shape PSO (calibrating each candidate would cost a render
and a lift apiece). The energies of different rounds are therefore measured against different
E_B targets.
E_J's 3D term stays in the fit though the build biases it (a heavier body's joints lift farther in
front: :data:`~swarmpose.tracking.lift.JOINT_RADIUS` is one per joint): neither leaving it out
nor correcting its targets like E_B's helps.

The bodies scored are :meth:`~swarmpose.body.shape_space.ShapeSpace.fitting_body`: for MakeHuman,
the tracking mesh moved out to enclose the full mesh's volume, which the decimation lowers by
about 2.4 %; matched to the depth as it is, the tracking mesh would make the full body that much
too large. The result's ``tracking_body`` is the plain tracking mesh, as a tracker loading the
fitted body makes it.

Key frames are chosen by farthest-point sampling of the tracked poses' joint angles and root
orientation, so that the fit sees the limbs in different configurations.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.body.parametric_sdf import signed_volume
from swarmpose.body.shape_space import ShapeSpace
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, PersonalisationError
from swarmpose.detect.joints import Joints2D
from swarmpose.gpu.context import ClContext
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.personalise import shape_stature
from swarmpose.personalise.depth_dropouts import fill_dropouts
from swarmpose.personalise.fit_settings import FitSettings
from swarmpose.personalise.lift_bias import LIMB_BONES, lift_bias, typical_depth
from swarmpose.personalise.own_pose_search import FIRST_STEP, LEAST_STEP, compass_search, own_pose_energy
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker, observed_depth
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.objective import JointTargets, Objective
from swarmpose.tracking.pso import PsoConfig, minimise

log = logging.getLogger(__name__)

MIN_FRAMES = 3
"""Fewest tracked frames a fit accepts."""


@dataclass(frozen=True)
class ShapeSample:
    """One frame of the person: the frame, its detection (None: none) and the pose (36,)
    the tracker found for it with the start body."""

    frame: Frame
    joints: Joints2D | None
    pose: np.ndarray


@dataclass
class ShapeFit:
    """The result: parameters ``x`` (D,) and by name, the full-resolution and tracking bodies, the key
    frames (indices into the samples that had a pose), the energy after each round (each against that
    round's E_B targets, see the module docstring), seconds, and the stature measured on the depth
    with the frames it was measured on (None: too few upright frames, or the term is off)."""

    x: np.ndarray
    parameters: dict[str, float]
    body: SkinnedBody
    tracking_body: SkinnedBody
    keyframes: list[int]
    energy: list[float] = field(default_factory=list)
    seconds: float = 0.0
    stature_m: float | None = None
    stature_frames: int = 0
    judged: int = 0  # shapes the last stage judged with poses of their own, the start's not counted (0: not run)


NOISE_AXES = 1.0
"""k of :func:`debiased_length`: how many axes across a bone carry the per-frame noise of the
lifted joints with the variance seen along it. The noise of J^e is mostly the 2D keypoints' (in
the image plane, where a walking person's limbs mostly lie: one axis across the limb); the lift's
depth is a window median and jitters less. k = 2 would be isotropic 3D noise."""
MAX_CORRECTION = 0.1
"""The most :func:`debiased_length` takes off, as a share of the median: beyond it the noise is
not small against the bone and the first-order correction no longer holds."""


def debiased_length(lengths: np.ndarray, noise_axes: float = NOISE_AXES) -> float:
    """A rigid bone's length (m) from its observed lengths (N,) m over frames (NaN: not seen),
    with the lengthening by noise removed.

    Noise n on the difference vector d = L·e + n of the two ends lengthens |d| on average:
    |d| ≈ L + n_par + |n_perp|^2 / (2L), whatever the sign of the noise. n_par is symmetric and
    makes the spread, so the median m ≈ L + E|n_perp|^2 / (2L) and the variance v ≈ var(n_par).
    With ``noise_axes`` (k) perpendicular axes of that variance each, E|n_perp|^2 = k·v and
    L ≈ m − k·v / (2m); v is the squared normalised MAD (1.4826·MAD)^2, robust to swapped or
    mislabelled keypoints. The correction is capped at :data:`MAX_CORRECTION` of m. NaN when
    no length is finite."""
    seen = np.asarray(lengths, float)
    seen = seen[np.isfinite(seen)]
    if seen.size == 0:
        return float("nan")
    m = float(np.median(seen))
    if m <= 0.0:
        return m
    spread = 1.4826 * float(np.median(np.abs(seen - m)))
    return m - min(noise_axes * spread * spread / (2.0 * m), MAX_CORRECTION * m)


def fitting_depth(frame: Frame) -> np.ndarray:
    """The depth (H, W) float32 m (0: none) the fit reads of ``frame``: invalid readings at 0,
    edge dropouts filled (:func:`~swarmpose.personalise.depth_dropouts.fill_dropouts`)."""
    return fill_dropouts(observed_depth(frame.depth))


def observed_bone_lengths(samples: Sequence[ShapeSample], body: SkinnedBody, intrinsics: Intrinsics,
                          min_score: float, noise_axes: float = NOISE_AXES) -> dict[tuple[str, str], float]:
    """Each :data:`LIMB_BONES` pair's length (m) over ``samples``: :func:`debiased_length` of the
    distances between the lifted joints J^e in the frames where both ends were detected with
    depth (pairs seen in fewer than 3 frames are left out)."""
    seen: dict[tuple[str, str], list[float]] = {b: [] for b in LIMB_BONES}
    for sample in samples:
        targets = JointTargets.from_detection(sample.joints, fitting_depth(sample.frame), intrinsics, body, min_score)
        where = {n: p for n, p in zip(targets.names, targets.xyz) if np.all(np.isfinite(p))}
        for a, b in LIMB_BONES:
            if a in where and b in where:
                seen[(a, b)].append(float(np.linalg.norm(where[a] - where[b])))
    return {bone: debiased_length(np.array(v), noise_axes) for bone, v in seen.items() if len(v) >= 3}


def bone_energy(body: SkinnedBody, observed: dict[tuple[str, str], float]) -> float:
    """E_B: mean |model bone length - observed| in cm over the observed bones (0 with none)."""
    if not observed:
        return 0.0
    diffs = [abs(float(np.linalg.norm(body.point(a) - body.point(b))) - length) for (a, b), length in observed.items()]
    return 100.0 * float(np.mean(diffs))


def spread_frames(poses: Sequence[np.ndarray], count: int) -> list[int]:
    """Indices of ``count`` poses (36,) spread out by farthest-point sampling over the joint
    angles and the root quaternion (rad / unitless), starting from the first."""
    if len(poses) <= count:
        return list(range(len(poses)))
    feats = np.stack([p[3:] for p in poses])
    chosen = [0]
    dist = np.linalg.norm(feats - feats[0], axis=1)
    while len(chosen) < count:
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(feats - feats[k], axis=1))
    return sorted(chosen)


class _KeyFrame:
    """One key frame's objective (the tracker's weights with E_S on at w_S = w_D), on a scorer of
    its own that keeps the frame's observation (its depth with dropouts filled)."""

    def __init__(self, sample: ShapeSample, body: SkinnedBody, intrinsics: Intrinsics, config: TrackerConfig,
                 tile: tuple[int, int], context: ClContext, tracker: BodyTracker):
        self.sample, self.pose = sample, np.asarray(sample.pose, float)
        try:
            scorer = ParticleScorer(body, intrinsics, tile, threshold=config.threshold_m, context=context)
        except ConfigError:  # the fit's finer tile needs more local memory than the device has (GPUs)
            scorer = ParticleScorer(body, intrinsics, config.tile, threshold=config.threshold_m, context=context)
        self.objective = Objective(body, intrinsics, scorer, replace(config.weights, silhouette=config.weights.depth))
        depth = fitting_depth(sample.frame)
        targets = JointTargets.from_detection(sample.joints, depth, intrinsics, body, config.min_score)
        self.objective.set_frame(depth, tracker.search_box(self.pose, targets), targets, self.pose)

    def energy(self, body: SkinnedBody) -> float:
        """The least E + w_D·E_S of this frame's pose with ``body`` over the root offsets of
        :data:`ROOT_OFFSETS_M` (see the module docstring)."""
        self.objective.set_body(body)
        poses = np.repeat(self.pose[None], len(ROOT_OFFSETS_M), axis=0)
        up = quaternion_to_matrix(self.pose[3:7])[:, 1]
        poses[:, :3] += ROOT_OFFSETS_M[:, :1] * up + ROOT_OFFSETS_M[:, 1:2] * np.array([0.0, 0.0, 1.0])
        total = np.asarray(self.objective(poses), float)
        best = int(np.argmin(total))
        self.best_pose = poses[best]
        return float(total[best])


ROOT_OFFSETS_M = np.array([(u, z) for u in (-0.06, -0.03, 0.0, 0.03, 0.06) for z in (-0.03, 0.0, 0.03)])
"""(K, 2) root offsets tried per key frame and candidate shape: along the body's up axis and the
camera's depth axis, m. A taller or shorter body moves its hips; holding the root where the start
body had it would tie the fit to the start shape."""


def fit_shape(space: ShapeSpace, samples: Sequence[ShapeSample], intrinsics: Intrinsics, config: TrackerConfig,
              settings: FitSettings | None = None, context: ClContext | None = None,
              progress: Callable[[str], None] | None = None) -> ShapeFit:
    """The shape of the person in ``samples`` (see the module docstring). ``config``: the
    tracker's settings (its weights, search budget and device); PersonalisationError when
    fewer than :data:`MIN_FRAMES` samples have a pose."""
    settings = settings or FitSettings()
    t0 = time.perf_counter()
    usable = [s for s in samples if s.pose is not None and np.all(np.isfinite(s.pose))]
    if len(usable) < MIN_FRAMES:
        raise PersonalisationError(f"only {len(usable)} of {len(samples)} frames were tracked (at least {MIN_FRAMES} "
                                   "needed): is a person in view, is the detector right for the source? Give more "
                                   "frames (personalize --frames, or a larger --personalize N) or a recording where "
                                   "the whole body is seen")
    if config.mode == "lift":
        raise PersonalisationError("the lift mode fits no body; personalise with mode hybrid, depth or joints")
    config = replace(config, max_people=1, coarse_share=0.0, limb_flips=False, limb_exchanges=False,
                     polish=0)  # the pose step: local
    context = context or ClContext.for_spec(config.device)
    x = space.start
    body = space.fitting_body(x)
    tracker = BodyTracker(body, intrinsics, config, context)
    chosen = spread_frames([s.pose for s in usable], settings.keyframes)
    keys = [_KeyFrame(usable[k], body, intrinsics, config, settings.tile, context, tracker) for k in chosen]
    rng = np.random.default_rng(settings.seed)
    pso = PsoConfig(particles=settings.particles, generations=settings.generations, variant="canonical")
    span = space.upper - space.lower

    observed = observed_bone_lengths(usable, body, intrinsics, config.min_score) if settings.bone_weight > 0 else {}
    bones = dict(observed)
    typical = [typical_depth(k.sample.frame) for k in keys]  # the frames' own: the same for every shape
    stature, measured = (shape_stature.measured_stature(usable, body, intrinsics, config.min_score)
                         if settings.stature_weight > 0 else (None, 0))
    if progress is not None and settings.stature_weight > 0:
        progress(f"stature on the depth: {'none' if stature is None else f'{stature:.3f} m'} ({measured} upright "
                 "frames measured)")

    def calibrate(x_now: np.ndarray) -> None:
        """E_B's lengths: the observed ones less the lift's bias on the full body of ``x_now`` at
        the key frames' current poses (see the module docstring)."""
        if not (observed and settings.debias_lift):
            return
        bias = lift_bias(space.full_body(x_now), [k.pose for k in keys], typical, intrinsics)
        bones.update({bone: length - bias.get(bone, 0.0) for bone, length in observed.items()})
        if progress is not None:
            progress("lift bias: " + ", ".join(f"{a.replace('left_', 'L ').replace('right_', 'R ')}-"
                                               f"{b.split('_', 1)[1]} {100 * v:+.1f} cm" for (a, b), v in bias.items()))

    def height_term(shaped: SkinnedBody) -> float:  # E_H
        return shape_stature.stature_energy(shape_stature.full_height(shaped), stature, settings.stature_weight)

    def energy_of(shaped: SkinnedBody) -> float:
        return (sum(k.energy(shaped) for k in keys) / len(keys) + settings.bone_weight * bone_energy(shaped, bones)
                + height_term(shaped))

    def shape_energy(candidates: np.ndarray) -> np.ndarray:
        return np.array([energy_of(space.fitting_body(cand)) for cand in candidates])

    def refit(shaped: SkinnedBody) -> float:
        """The pose step: every key frame's pose refitted with ``shaped`` by the tracker's own
        search from the best root offset of its last pose; returns the mean shape energy."""
        tracker.set_body(shaped)
        for key in keys:
            key.energy(shaped)
            pose = key.best_pose
            for _ in range(settings.pose_steps):
                tracker.reset()
                tracker.previous = pose
                tracker.history.restart(pose)
                result = tracker.step(key.sample.frame, key.sample.joints)
                if result.pose is not None and result.state != "lost":
                    pose = np.asarray(result.pose, float)
            key.pose = pose
        return energy_of(shaped)

    x, first = _sweep(space, keys, refit, settings.sweep, calibrate)
    if progress is not None:
        progress(f"sweep: start {', '.join(f'{k} {v:.3f}' for k, v in space.parameters(x).items())} "
                 f"(energy {first:.2f})")
    energies: list[float] = [first]
    for round_ in range(settings.rounds):
        calibrate(x)
        start = np.clip(x + rng.normal(0.0, 0.15 / (1 + round_), (pso.particles, len(x))) * span,
                        space.lower, space.upper)
        start[0] = x
        best = minimise(shape_energy, start, space.lower, space.upper, rng, pso)
        x = space.clip(best.best)
        energies.append(refit(space.fitting_body(x)))
        if progress is not None:
            progress(f"round {round_ + 1}/{settings.rounds}: energy {best.value:.2f}, "
                     + ", ".join(f"{k} {v:.3f}" for k, v in space.parameters(x).items()))
    count = 0  # the last stage, where the space's steps are tuned for it (MakeHuman's)
    if settings.own_pose_rounds > 0 and settings.own_pose_candidates > 0 and space.own_pose_stage:
        starts = [k.pose for k in keys]
        def own_pose_value(cand: np.ndarray) -> float:  # E + w_D·E_S at poses of its own, and E_H (no E_B)
            shaped = space.fitting_body(cand)
            return own_pose_energy(keys, starts, shaped, settings.own_pose_rounds) + height_term(shaped)
        x, value, count = compass_search(own_pose_value, x, space.lower, space.upper, FIRST_STEP, LEAST_STEP,
                                         settings.own_pose_candidates)
        if progress is not None:
            progress(f"own poses: {count} shapes judged, energy {value:.2f} (at polished poses, without E_B), "
                     + ", ".join(f"{k} {v:.3f}" for k, v in space.parameters(x).items()))
    full = space.full_body(x)
    return ShapeFit(x, space.parameters(x), full, space.tracking_body(x), chosen, energies,
                    time.perf_counter() - t0, stature, measured, count)


def _sweep(space: ShapeSpace, keys: list[_KeyFrame], refit: Callable[[SkinnedBody], float],
           grid: dict[str, tuple[float, ...]],
           calibrate: Callable[[np.ndarray], None] = lambda x: None) -> tuple[np.ndarray, float]:
    """Stage 0: the start shape with each combination of ``grid``'s values ({parameter: values};
    parameters the space lacks are skipped), each with its own pose refit, so that poses tracked
    with the start body do not tie the fit to it; ``calibrate(x)`` is called before each
    candidate's refit (E_B's lift bias of that candidate). Returns the best parameters and their
    energy; the key frames keep the best candidate's poses."""
    import itertools

    axes = [(space.names.index(n), v) for n, v in grid.items() if n in space.names]
    candidates = [space.start]
    for combo in itertools.product(*(v for _, v in axes)):
        x = space.start
        for (i, _), value in zip(axes, combo):
            x[i] = value
        x = space.clip(x)
        if not any(np.allclose(x, c) for c in candidates):  # e.g. the start itself: its fit would repeat
            candidates.append(x)
    initial = [k.pose for k in keys]
    best, best_energy, best_poses = candidates[0], np.inf, initial
    for x in candidates:
        for k, pose in zip(keys, initial):
            k.pose = pose
        calibrate(x)
        energy = refit(space.fitting_body(x))
        if energy < best_energy:
            best, best_energy, best_poses = x, energy, [k.pose for k in keys]
    for k, pose in zip(keys, best_poses):
        k.pose = pose
    return best, float(best_energy)


def body_measures(body: SkinnedBody) -> dict[str, float]:
    """``height_m`` (vertical extent of the rest mesh) and ``volume_l`` (enclosed volume of the
    rest mesh, litres, by the divergence theorem) of ``body``."""
    volume = abs(signed_volume(np.asarray(body.vertices, dtype=np.float64), np.asarray(body.triangles)))
    return {"height_m": round(body.height, 4), "volume_l": round(volume * 1000.0, 2)}
