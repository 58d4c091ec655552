"""The shape fit's last stage: candidate shapes judged with poses of their own.

:func:`~swarmpose.personalise.personalise.fit_shape` alternates a shape step with the key frames'
poses held and a pose step, and poses fitted with one shape favour shapes like it: the
alternation, started from poses tracked with the start body, settles near where it started. With
every key frame's pose polished anew for each body, a truer shape scores lower. This stage does
that judgement during the fit: each candidate shape gets its own poses.

A candidate's energy (:func:`own_pose_energy`): every key frame's pose, from where the
alternation left it, is moved to the candidate's best root offset
(:meth:`~swarmpose.personalise.personalise._KeyFrame.energy`) and polished on that frame's objective
with the candidate's body (:func:`~swarmpose.tracking.pose_polish.polish_pose`, every
coordinate); the energy is the mean of the polished values plus the stature term E_H. The bone
term E_B is left out: its lengths are corrected by the lift's bias on the shape being judged, which
costs a render and a lift per shape (:mod:`~swarmpose.personalise.personalise`), more than the judgement
itself. The polish
of key frame i draws the same random numbers for every candidate (common random numbers), so the
energy is a deterministic function of the shape: two candidates differ by their shapes, not by
the luck of their polish.

The search (:func:`compass_search`): from the alternation's result, each parameter moved by
±step (a share of its range: 0.15 of a MakeHuman slider's 0..1 at first), the best improvement
taken, the step halved when none improves, until the step falls below ``min_step`` (at
:data:`FIRST_STEP` and :data:`LEAST_STEP`: steps of 0.15 and 0.075 only) or the budget is spent (the
round that reaches it finishes: up to 2D - 1 more, D the parameters). Only MakeHuman's space gets
the stage (:attr:`~swarmpose.body.shape_space.ShapeSpace.own_pose_stage`): the steps are tuned for
its sliders, and on the built-in body a first step would be 9 cm of stature. Each judgement costs a
polish of every key frame, so the budget is tens of candidates, which rules out a population
method; scipy's bounded local methods (Powell, Nelder-Mead) start with a line search or a simplex
of one candidate per dimension and do not take a budget of whole candidates with a fixed step
pattern.

The budget stays small because the judgement resolves the energy only to about one part in a
thousand: a larger search finds shapes of lower energy that are not truer ones.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from swarmpose.tracking.pose_polish import polish_pose

POLISH_SEED = 1000
"""Key frame i's polish draws from ``default_rng(POLISH_SEED + i)`` for every candidate."""
FIRST_STEP, LEAST_STEP = 0.15, 0.04
"""The shape fit's search: its first step and the least, as shares of each parameter's range."""


def own_pose_energy(keys: Sequence, starts: Sequence[np.ndarray], body, rounds: int) -> float:
    """Mean over ``keys`` (the fit's key frames, each with ``objective``, ``energy(body)`` and
    ``best_pose``) of the key frame's E + w_D·E_S after its pose was moved to ``body``'s best root
    offset from ``starts[i]`` (36,) and polished ``rounds`` rounds with ``body``."""
    total = 0.0
    for i, (key, start) in enumerate(zip(keys, starts)):
        key.pose = np.asarray(start, float)
        key.energy(body)
        _, value = polish_pose(key.objective, key.best_pose, rounds, np.random.default_rng(POLISH_SEED + i))
        total += value
    return total / len(keys)


def compass_search(energy: Callable[[np.ndarray], float], x: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                   step: float, min_step: float, budget: int) -> tuple[np.ndarray, float, int]:
    """Minimise ``energy`` over the box ``lower``..``upper`` (D,) from ``x`` (D,): each round
    judges every parameter moved by ±``step`` times its range ``upper - lower`` (clipped to the
    box; moves the box cancels are skipped), moves to the best candidate if it beats the current
    one, else halves the step; stops when the step falls below ``min_step`` or ``budget``
    candidates have been judged (a round is finished once begun). A point judged before (the one a
    move came from is a candidate of the next round) takes its known energy instead of another
    call; it still counts against the budget. Returns (x, its energy, candidates judged)."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    x = np.clip(np.asarray(x, float), lower, upper)
    span = upper - lower
    known: list[tuple[np.ndarray, float]] = []

    def judge(c: np.ndarray) -> float:
        for point, v in known:
            if np.allclose(point, c, rtol=0.0, atol=1e-12):
                return v
        known.append((c, float(energy(c))))
        return known[-1][1]

    value, judged = judge(x), 0
    while step >= min_step and judged < budget:
        candidates = []
        for i in range(len(x)):
            for sign in (-1.0, 1.0):
                c = x.copy()
                c[i] = np.clip(c[i] + sign * step * span[i], lower[i], upper[i])
                if not np.allclose(c, x):
                    candidates.append(c)
        if not candidates:
            break
        values = [judge(c) for c in candidates]
        judged += len(candidates)
        best = int(np.argmin(values))
        if values[best] < value:
            x, value = candidates[best], values[best]
        else:
            step /= 2.0
    return x, value, judged
