"""PSO: the constriction constant by hand, convergence of the two update forms on test
functions, bounds, perturbation bookkeeping, determinism and sub-swarms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmpose.core.errors import ConfigError
from swarmpose.tracking.pso import PsoConfig, PsoResult, constriction_factor, group_leaders, group_members, minimise


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum(x * x, axis=1)


def rastrigin(x: np.ndarray) -> np.ndarray:
    return 10 * x.shape[1] + np.sum(x * x - 10 * np.cos(2 * np.pi * x), axis=1)


def run(f, dim: int, lim: float, seed: int, **cfg):
    rng = np.random.default_rng(seed)
    start = rng.uniform(-lim, lim, (64, dim))
    return minimise(f, start, np.full(dim, -lim), np.full(dim, lim), rng, PsoConfig(**cfg))


def test_constriction_factor_by_hand():
    psi = 4.1
    assert constriction_factor(2.8, 1.3) == pytest.approx(2 / abs(2 - psi - math.sqrt(psi * psi - 4 * psi)))
    assert constriction_factor(2.8, 1.3) == pytest.approx(0.72984, abs=1e-5)
    with pytest.raises(ConfigError):
        constriction_factor(2.0, 2.0)


def test_constriction_converges_and_the_printed_form_does_not():
    """Eq. (7) as printed (ω on the inertia only, c1 + c2 = 4.1) stalls far from the optimum
    of a 10-D sphere (median 0.13 measured); Clerc–Kennedy's form reaches ~1e-12."""
    seed = int(np.random.default_rng().integers(1 << 30))
    con = [run(sphere, 10, 5.0, seed + s, generations=200, variant="canonical").value for s in range(3)]
    printed = [run(sphere, 10, 5.0, seed + s, generations=200, variant="canonical", update="printed").value
               for s in range(3)]
    assert np.median(con) < 1e-6, f"seed {seed}"
    assert np.median(printed) > 1e-3, f"seed {seed}"
    ras_con = np.median([run(rastrigin, 10, 5.12, seed + s, generations=200, variant="canonical").value
                         for s in range(3)])
    ras_printed = np.median([run(rastrigin, 10, 5.12, seed + s, generations=200, variant="canonical",
                                 update="printed").value for s in range(3)])
    assert ras_con < ras_printed, f"seed {seed}"


def test_positions_stay_within_bounds_and_history_is_monotone():
    seen = []

    def f(x):
        seen.append(x.copy())
        return np.sum((x - 3.0) ** 2, axis=1)  # optimum outside the box: particles press on the bound

    rng = np.random.default_rng(1)
    lo, hi = np.full(4, -1.0), np.array([1.0, 1.0, 2.0, np.inf])
    r = minimise(f, rng.uniform(-3, 3, (16, 4)), lo, hi, rng, PsoConfig(particles=16, generations=30))
    allx = np.concatenate(seen)
    assert np.all(allx >= lo - 1e-12) and np.all(allx <= hi + 1e-12)
    assert np.allclose(r.best[:3], [1.0, 1.0, 2.0], atol=1e-3)
    assert r.best[3] == pytest.approx(3.0, abs=1e-2)
    assert np.all(np.diff(r.history) <= 0)
    assert r.evaluations == 16 * 31 == len(allx)


def test_perturbation_moves_particles_but_keeps_the_best():
    calls = []

    def perturb(x, rng):
        calls.append(len(x))
        return x + rng.normal(0, 1.0, x.shape)

    rng = np.random.default_rng(2)
    r = minimise(sphere, rng.uniform(-5, 5, (32, 6)), np.full(6, -5.0), np.full(6, 5.0), rng,
                 PsoConfig(particles=32, generations=24, perturb_every=8, perturb_fraction=0.5), perturb=perturb)
    assert len(calls) == 3 and all(0 < c < 32 for c in calls)
    assert np.all(np.diff(r.history) <= 0)
    canonical = minimise(sphere, np.random.default_rng(2).uniform(-5, 5, (32, 6)), np.full(6, -5.0),
                         np.full(6, 5.0), np.random.default_rng(2), PsoConfig(particles=32, generations=24,
                                                                                 variant="canonical"),
                         perturb=perturb)
    assert len(calls) == 3, "the canonical variant never perturbs"
    assert canonical.value < 1.0


def test_seeded_runs_repeat_and_project_is_applied():
    def unit(x):
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    target = np.array([0.0, 0.6, 0.8])
    f = lambda x: np.linalg.norm(x - target, axis=1)
    a = minimise(f, np.random.default_rng(5).normal(size=(16, 3)), np.full(3, -1.0), np.full(3, 1.0),
                 np.random.default_rng(5), PsoConfig(particles=16, generations=40), project=unit)
    b = minimise(f, np.random.default_rng(5).normal(size=(16, 3)), np.full(3, -1.0), np.full(3, 1.0),
                 np.random.default_rng(5), PsoConfig(particles=16, generations=40), project=unit)
    assert np.array_equal(a.best, b.best)
    assert np.linalg.norm(a.best) == pytest.approx(1.0)
    assert a.value < 0.02


def test_bad_configs():
    for kw in ({"particles": 0}, {"generations": 0}, {"variant": "x"}, {"update": "y"}, {"perturb_every": 0}):
        with pytest.raises(ConfigError):
            PsoConfig(**kw)


def test_refine_switches_the_objective_once_and_rescores_the_personal_bests():
    """A coarse objective (shifted optimum) for the first half, the true one after: the result
    is the true optimum's, its value the true objective's, and P more evaluations are counted."""
    calls = {"coarse": 0, "fine": 0}
    state = {"fine": False}

    def objective(x: np.ndarray) -> np.ndarray:
        calls["fine" if state["fine"] else "coarse"] += len(x)
        centre = 0.0 if state["fine"] else 0.3
        return np.sum((x - centre) ** 2, axis=1)

    rng = np.random.default_rng(5)
    start = rng.uniform(-1, 1, (32, 4))
    result = minimise(objective, start, np.full(4, -1.0), np.full(4, 1.0), rng, PsoConfig(32, 40),
                      refine_at=20, refine=lambda: state.update(fine=True))
    assert calls == {"coarse": 32 * 20, "fine": 32 * 21 + 32}  # generations 20..40 and the rescoring
    assert result.evaluations == 32 * 41 + 32
    assert np.allclose(result.best, 0.0, atol=0.02) and result.value == pytest.approx(np.sum(result.best ** 2))


def test_personal_bests_are_returned_with_their_values():
    """Every particle's best position and value at the end: the values are the objective's at
    those positions, and the result's best is the lowest of them."""
    def sphere(x: np.ndarray) -> np.ndarray:
        return np.sum((x - 0.3) ** 2, axis=1)

    rng = np.random.default_rng(4)
    start = rng.uniform(-1, 1, (12, 3))
    result = minimise(sphere, start, np.full(3, -1.0), np.full(3, 1.0), rng, PsoConfig(particles=12, generations=15))
    assert result.personal_bests.shape == (12, 3) and result.personal_values.shape == (12,)
    np.testing.assert_allclose(result.personal_values, sphere(result.personal_bests))
    k = int(np.argmin(result.personal_values))
    np.testing.assert_array_equal(result.best, result.personal_bests[k])
    assert result.value == result.personal_values[k]


def test_group_leaders_by_hand():
    values = np.array([5.0, 1.0, 3.0, 0.5, 4.0, 2.0])
    groups = np.array([0, 0, 1, 0, 1, 2])
    assert group_leaders(values, group_members(groups)).tolist() == [3, 3, 2, 3, 2, 5]


def limb_and_rest(x: np.ndarray) -> np.ndarray:
    """A tracker's frame in 6-D: x0 a limb with a wide wrong basin at 0 (value 0) and a narrow
    right one at 4 (value -1), x1..x5 the rest of the pose, right at 0."""
    limb = np.minimum(x[:, 0] ** 2, 16.0 * (x[:, 0] - 4.0) ** 2 - 1.0)
    return limb + 4.0 * np.sum(x[:, 1:] ** 2, axis=1)


def track_and_hypothesis(rng: np.random.Generator, size: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """64 starts: the track's around the wrong limb, ``size`` around the right one (one exactly
    on it), all with the rest of the pose a frame old (at 1); and their groups (1: the hypothesis)."""
    start = np.empty((64, 6))
    start[:, 0] = rng.uniform(-0.3, 0.3, 64)
    start[:, 1:] = 1.0 + rng.uniform(-0.5, 0.5, (64, 5))
    start[-size:, 0] = 4.0 + rng.uniform(-0.15, 0.15, size)
    start[-size:, 1:] = 1.0 + rng.uniform(-0.25, 0.25, (size, 5))
    start[-size] = [4.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    groups = np.zeros(64, dtype=int)
    groups[-size:] = 1
    return start, groups


def test_a_sub_swarm_refines_a_narrow_right_basin_that_the_whole_swarm_leaves():
    """With the rest of the pose unrefined, the hypothesis' particles score worse than the
    track's at first; following the swarm's best they leave the narrow right basin (measured:
    1 of these 10 seeds keeps it, 8 of 40), following their own group's best before generation
    48 they refine it and win (10 of 10, 40 of 40)."""
    lo, hi = np.full(6, -10.0), np.full(6, 10.0)
    found = {True: 0, False: 0}
    for seed in range(10):
        for grouped in (True, False):
            rng = np.random.default_rng(seed)
            start, groups = track_and_hypothesis(rng)
            assert limb_and_rest(start[-12:-11])[0] > np.min(limb_and_rest(start[:-12]))  # worse at first
            result = minimise(limb_and_rest, start, lo, hi, rng, PsoConfig(generations=64),
                              perturb=lambda x, r: x + r.uniform(-0.5, 0.5, x.shape),
                              groups=groups if grouped else None, merge_at=48)
            found[grouped] += bool(abs(result.best[0] - 4.0) < 0.2 and result.value < -0.9)
    assert found[True] == 10
    assert found[False] <= 5


def test_groups_must_label_every_particle():
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError, match="one label per particle"):
        minimise(sphere, rng.uniform(-1, 1, (8, 2)), np.full(2, -1.0), np.full(2, 1.0), rng,
                 PsoConfig(particles=8, generations=2), groups=np.zeros(7, dtype=int), merge_at=1)


def test_one_group_is_the_single_swarm_draw_for_draw():
    """All particles in one group: the same run as without groups, to the last bit (the tracker
    with ``hypotheses = 0`` is the tracker before sub-swarms)."""
    runs = []
    for groups in (None, np.zeros(64, dtype=int)):
        rng = np.random.default_rng(3)
        start, _ = track_and_hypothesis(rng)
        runs.append(minimise(limb_and_rest, start, np.full(6, -10.0), np.full(6, 10.0), rng, PsoConfig(generations=30),
                             perturb=lambda x, r: x + r.uniform(-0.5, 0.5, x.shape), groups=groups, merge_at=20))
    assert np.array_equal(runs[0].personal_bests, runs[1].personal_bests)
    assert np.array_equal(runs[0].history, runs[1].history)


def test_after_the_merge_a_worse_group_joins_the_best():
    """Two groups in two wide basins, the better at 0, over 10 seeds: never merged, the group
    started at 4 keeps every personal best in its own basin; merged at generation 10, its
    particles are pulled to the best of all and some find the better basin (measured: 16 of
    160 personal bests within 1.5 of 0; the strong pull to each particle's own best, c1 = 2.8,
    holds the rest)."""
    def basins(x: np.ndarray) -> np.ndarray:
        return np.minimum(np.sum(x ** 2, axis=1), np.sum((x - 4.0) ** 2, axis=1) + 1.0)

    moved = {10: 0, 1000: 0}
    for merge_at in moved:
        for seed in range(10):
            rng = np.random.default_rng(seed)
            start = np.concatenate([rng.uniform(-0.5, 0.5, (16, 3)), 4.0 + rng.uniform(-0.5, 0.5, (16, 3))])
            result = minimise(basins, start, np.full(3, -10.0), np.full(3, 10.0), rng,
                              PsoConfig(particles=32, generations=60, variant="canonical"),
                              groups=np.repeat([0, 1], 16), merge_at=merge_at)
            moved[merge_at] += int(np.sum(np.linalg.norm(result.personal_bests[16:], axis=1) < 1.5))
    assert moved[1000] == 0, "never merged: the second group stays in its own basin"
    assert moved[10] >= 8, moved


def test_the_best_among_some_particles_skips_the_others_and_non_finite_values():
    """Hand-set values: the best of the chosen particles is the lowest finite one among them, not
    the swarm's best; None when every chosen one is non-finite or none is chosen."""
    values = np.array([0.5, 2.0, np.nan, 1.0, np.inf])
    result = PsoResult(np.zeros(2), 0.5, values[:1], 5, np.zeros((5, 2)), values)
    assert result.best_among(np.array([False, True, True, True, True])) == 3
    assert result.best_among(np.ones(5, bool)) == 0
    assert result.best_among(np.array([False, False, True, False, True])) is None
    assert result.best_among(np.zeros(5, bool)) is None
