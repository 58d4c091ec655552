"""The block-by-block swarm: each particle moves one block of a shared context, every row is a whole
pose, and on a problem whose blocks are independent it beats the whole swarm at the same cost."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.core.errors import ConfigError
from swarmpose.tracking.block_pso import BLOCKS, WHOLE_SHARE, block_of_particles, minimise_blocks, whole_then_blocks
from swarmpose.tracking.pso import PsoConfig, minimise
from swarmpose.tracking.search import pose_bounds, renormalise

TARGET = np.random.default_rng(7).uniform(-0.4, 0.4, 36)


def separable(x: np.ndarray) -> np.ndarray:
    """(P,) a sum over the pose's columns of a bowl with ripples, least (0) at TARGET."""
    d = x - TARGET
    return np.sum(d * d + 0.3 * np.abs(np.sin(5.0 * d)), axis=1)


def recording(f):
    """``f`` wrapped to keep a copy of every batch it scores, and that list."""
    calls = []

    def wrapped(x):
        calls.append(x.copy())
        return f(x)

    return wrapped, calls


def box(dim: int = 36) -> tuple[np.ndarray, np.ndarray]:
    return np.full(dim, -2.0), np.full(dim, 2.0)


def test_the_blocks_hold_every_column_of_the_pose_once():
    columns = np.sort(np.concatenate(BLOCKS))
    assert np.array_equal(columns, np.arange(36))


def test_particles_are_dealt_to_the_blocks_after_the_context():
    assert block_of_particles(8, 3).tolist() == [-1, 0, 1, 2, 0, 1, 2, 0]
    with pytest.raises(ConfigError, match="at least 7 particles"):
        block_of_particles(6, 6)


def test_each_particle_moves_one_block_of_the_context_and_row_0_is_the_context():
    f, calls = recording(separable)
    lo, hi = box()
    start = np.random.default_rng(0).uniform(-0.6, 0.6, (20, 36))
    result = minimise_blocks(f, start, lo, hi, np.random.default_rng(1), PsoConfig(particles=20, generations=5))
    assert len(calls) == 6 and result.evaluations == 20 * 6
    member = block_of_particles(20, len(BLOCKS))
    for rows in calls[1:]:
        for i in range(1, 20):
            moved = np.flatnonzero(rows[i] != rows[0])
            assert np.isin(moved, BLOCKS[member[i]]).all()
    contexts = [rows[0] for rows in calls[1:]]
    assert any(not np.array_equal(a, b) for a, b in zip(contexts, contexts[1:]))  # the context moved on


def test_the_result_is_the_best_whole_pose_scored_and_each_personal_best_its_own_value():
    seen = []

    def f(x):
        values = separable(x)
        seen.append(values)
        return values

    lo, hi = box()
    start = np.random.default_rng(2).uniform(-0.6, 0.6, (32, 36))
    result = minimise_blocks(f, start, lo, hi, np.random.default_rng(3), PsoConfig(particles=32, generations=6))
    assert result.value == pytest.approx(min(v.min() for v in seen))
    assert separable(result.best[None])[0] == pytest.approx(result.value)
    assert np.allclose(separable(result.personal_bests), result.personal_values)
    assert np.all(np.diff(result.history) <= 0) and result.history[-1] == result.value


def test_a_separable_problem_goes_further_block_by_block_than_with_the_whole_swarm():
    """Same start, same cost (64 particles, 8 generations): the block swarm ends lower in every one of
    six runs (0.55-0.86 of its value), and the median below 0.8 of the whole swarm's (0.62)."""
    lo, hi = box()
    whole, blocks = [], []
    for seed in range(6):
        start = np.random.default_rng(seed).uniform(-0.6, 0.6, (64, 36))
        config = PsoConfig(particles=64, generations=8, variant="canonical")
        whole.append(minimise(separable, start, lo, hi, np.random.default_rng(seed), config).value)
        blocks.append(minimise_blocks(separable, start, lo, hi, np.random.default_rng(seed), config).value)
    assert all(b < w for b, w in zip(blocks, whole)), (blocks, whole)
    assert np.median(blocks) < 0.8 * np.median(whole)


def test_poses_stay_within_bounds_unit_quaternions_and_nan_never_wins():
    lo, hi = pose_bounds()
    rng = np.random.default_rng(4)
    start = np.zeros((24, 36))
    start[:, 2], start[:, 4] = 2.5, 1.0  # 2.5 m away, upright
    start[:, 7:] = rng.uniform(-0.3, 0.3, (24, 29))
    start = np.clip(start, lo, hi)
    calls = []

    def f(x):
        calls.append(x.copy())
        values = np.sum((x[:, 7:] - 5.0) ** 2, axis=1)  # the angles' optimum beyond their limits
        values[::3] = np.nan
        return values

    result = minimise_blocks(f, start, lo, hi, rng, PsoConfig(particles=24, generations=6), renormalise)
    rows = np.concatenate(calls)
    assert np.all(rows >= lo - 1e-9) and np.all(rows <= hi + 1e-9)
    assert np.allclose(np.linalg.norm(rows[:, 3:7], axis=1), 1.0)
    assert np.isfinite(result.value) and np.all(np.isfinite(result.best))


def test_a_proposal_names_the_one_block_it_changes():
    from swarmpose.tracking.block_pso import changed_block

    centre = np.zeros(36)
    arm = centre.copy()
    arm[BLOCKS[3][:2]] = 0.4
    both = arm.copy()
    both[BLOCKS[4][0]] = 0.1
    assert changed_block(arm, centre) == 3
    assert changed_block(centre, centre) is None and changed_block(both, centre) is None


def test_a_proposal_starts_a_particle_of_its_block_and_is_scored_in_the_context():
    """A proposal that moves one block to that block's optimum, far outside the start's spread: in the
    first generation after the start one particle of that block's sub-swarm holds it in the context,
    and the result keeps it; without it the 8 generations leave that block far off."""
    lo, hi = box()
    rng = np.random.default_rng(5)
    centre = TARGET.copy()
    centre[BLOCKS[2]] += 1.2  # the left arm far from its optimum, the rest at theirs
    start = centre + rng.uniform(-0.05, 0.05, (32, 36))
    start[0] = centre
    proposal = centre.copy()
    proposal[BLOCKS[2]] = TARGET[BLOCKS[2]]
    f, calls = recording(separable)
    config = PsoConfig(particles=32, generations=8)
    with_it = minimise_blocks(f, start, lo, hi, np.random.default_rng(6), config, proposals=[(2, proposal)])
    member = block_of_particles(32, len(BLOCKS))
    held = [i for i in np.flatnonzero(member == 2) if np.allclose(calls[1][i, BLOCKS[2]], TARGET[BLOCKS[2]])]
    assert len(held) == 1 and np.allclose(np.delete(calls[1][held[0]], BLOCKS[2]), np.delete(calls[1][0], BLOCKS[2]))
    without = minimise_blocks(separable, start, lo, hi, np.random.default_rng(6), config)
    off = np.abs(without.best[BLOCKS[2]] - TARGET[BLOCKS[2]]).max()
    assert np.abs(with_it.best[BLOCKS[2]] - TARGET[BLOCKS[2]]).max() < 0.1 < off


def test_the_frame_search_runs_the_whole_swarm_first_then_the_blocks_at_the_same_cost():
    f, calls = recording(separable)
    lo, hi = box()
    start = np.random.default_rng(8).uniform(-0.6, 0.6, (32, 36))
    config = PsoConfig(particles=32, generations=12)
    result = whole_then_blocks(f, start, lo, hi, np.random.default_rng(9), config, proposals=[(2, TARGET)])
    first = round(WHOLE_SHARE * 12)
    assert len(calls) == 13 and result.evaluations == 32 * 13 and len(result.history) == 13
    member = block_of_particles(32, len(BLOCKS))
    for k, rows in enumerate(calls[1:], start=1):
        one_block = all(np.isin(np.flatnonzero(rows[i] != rows[0]), BLOCKS[member[i]]).all() for i in range(1, 32))
        assert one_block == (k > first), k  # the whole swarm moves every column, the blocks one block each
    assert np.all(np.diff(result.history) <= 0)
    assert result.value == pytest.approx(min(separable(c).min() for c in calls))

