"""Sub-swarms for the frame's best hypotheses: which proposals get one, where their particles
start, and when there is no room for them."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import ANGLE_LIMITS
from swarmpose.tracking.hypotheses import GROUP_SHARE, SPREAD_SHARE, hypothesis_groups

MIDDLE = ANGLE_LIMITS.mean(axis=1)


def proposals_and_score(count: int = 5):
    """``count`` poses (36,) with distinct angles (within Table 1's limits, 0.01 rad apart),
    scored by their first angle's distance from proposal 3's (so 3 is best, then 2 or 4 ...)."""
    poses = [np.zeros(36) for _ in range(count)]
    for k, pose in enumerate(poses):
        pose[3] = 1.0
        pose[7:] = MIDDLE + 0.01 * k
    return poses, lambda x: np.abs(x[:, 7] - poses[3][7]) + 1e-3 * x[:, 7]


def test_the_best_proposals_get_the_last_particles_spread_around_them():
    poses, score = proposals_and_score()
    start = np.full((64, 36), 7.0)
    groups = hypothesis_groups(score, poses, start, 2, 0.4, np.random.default_rng(0))
    size = round(GROUP_SHARE * 64)
    assert size == 12
    assert groups.tolist() == [0] * 40 + [2] * 12 + [1] * 12
    assert np.all(start[:40] == 7.0), "the track's particles are left as they were"
    best, second = start[52:], start[40:52]
    assert np.array_equal(best[0], poses[3]) and np.array_equal(second[0], poses[2])  # 2 ties 4, but lower
    # the rest of each block within half the track's angle radius of its proposal
    assert np.all(np.abs(best[:, 7:] - poses[3][7:]) <= SPREAD_SHARE * 0.4 + 1e-9)
    assert np.all(np.abs(best[:, :3] - poses[3][:3]) <= 0.02 + 1e-9)
    assert np.std(best[:, 7:]) > 0.05, "spread, not copies"


def test_no_groups_without_proposals_count_or_room():
    poses, score = proposals_and_score()
    rng = np.random.default_rng(1)
    assert hypothesis_groups(score, [], np.zeros((64, 36)), 2, 0.4, rng) is None
    assert hypothesis_groups(score, poses, np.zeros((64, 36)), 0, 0.4, rng) is None
    assert hypothesis_groups(score, poses, np.zeros((3, 36)), 2, 0.4, rng) is None  # the track keeps 2
    assert np.bincount(hypothesis_groups(score, poses, np.zeros((4, 36)), 2, 0.4, rng)).tolist() == [2, 2]
    one = hypothesis_groups(score, poses[:1], np.zeros((64, 36)), 3, 0.4, rng)
    assert one.max() == 1 and np.sum(one == 1) == 12, "as many groups as proposals at most"
    small = hypothesis_groups(score, poses, np.zeros((16, 36)), 2, 0.4, rng)
    assert np.bincount(small).tolist() == [10, 3, 3], "a smaller swarm, smaller groups"


def test_the_tracks_own_seeds_are_never_covered():
    """``keep`` rows at the front (the previous solution, its history, the challenger) stay as they
    were: a small swarm gets fewer sub-swarms, or none."""
    poses, score = proposals_and_score()
    for particles, keep, expected in ((12, 11, None), (12, 10, 1), (12, 8, 2), (16, 10, 2), (8, 6, 1), (8, 7, None)):
        start = np.full((particles, 36), 7.0)
        groups = hypothesis_groups(score, poses, start, 2, 0.4, np.random.default_rng(2), keep=keep)
        assert np.all(start[:keep] == 7.0), (particles, keep)
        assert (groups is None if expected is None else groups.max() == expected), (particles, keep, groups)


def test_a_proposal_that_scores_nan_gets_no_sub_swarm():
    poses, _ = proposals_and_score(3)
    groups = hypothesis_groups(lambda x: np.array([np.nan, 1.0, np.inf]), poses, np.zeros((64, 36)), 2, 0.4,
                               np.random.default_rng(3))
    assert groups.max() == 1 and np.sum(groups == 1) == 12
    assert hypothesis_groups(lambda x: np.full(len(x), np.nan), poses, np.zeros((64, 36)), 2, 0.4,
                             np.random.default_rng(3)) is None
