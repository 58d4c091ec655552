"""The shape fit's settings (:func:`swarmpose.personalise.personalise.fit_shape`), declared once, in a module
light enough for the command line to read its defaults without loading the fit."""

from __future__ import annotations

from dataclasses import dataclass, field

STATURE_WEIGHT = 1.0
"""E_H: energy per cm that a body's rest height lies outside the stature's band: about three times the
slope of the fit's own energy over height, so the band bounds the fit and the objective chooses inside it
(:mod:`swarmpose.personalise.shape_stature`)."""

BONE_WEIGHT = 5.0
"""w_B: the bone-length term's weight per cm of mean difference."""

SWEEP = {"gender": (0.0, 1.0), "height": (0.2, 0.5, 0.8)}
"""Stage 0's grid (see :func:`swarmpose.personalise.personalise._sweep`): parameters by name, 0..1 (the
built-in body's height is its 0..1 slider over 1.45-2.05 m; it has no gender)."""


@dataclass(frozen=True)
class FitSettings:
    """How hard :func:`~swarmpose.personalise.personalise.fit_shape` works: key frames, alternation rounds, the
    shape PSO's particles and generations, the fit's depth tile (finer than tracking's: it runs once), the
    seed, the last stage's budget."""

    keyframes: int = 12
    rounds: int = 3
    particles: int = 16
    generations: int = 16
    tile: tuple[int, int] = (96, 96)  # falls back to the tracker's where the device lacks local memory
    seed: int = 0
    pose_steps: int = 2
    bone_weight: float = BONE_WEIGHT
    debias_lift: bool = True  # take the lift's own lengthening (lift_bias) off the observed limb lengths
    stature_weight: float = STATURE_WEIGHT  # E_H (0: off), see shape_stature
    sweep: dict[str, tuple[float, ...]] = field(default_factory=lambda: dict(SWEEP))
    own_pose_rounds: int = 60  # the last stage's polish per key frame and candidate (0: no last stage)
    own_pose_candidates: int = 40  # its budget of candidates (own_pose_search.compass_search; 0: no last stage)
