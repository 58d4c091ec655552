"""Association of tracks and observations: costs, gate, Hungarian pairing, colour looks; and the
multi-person scores (per-person Δ, switches, MOTA) on hand-made cases."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.people.association import NO_PAIR, assign, bhattacharyya, colour_histogram, pair_costs
from swarmpose.sim.people_metrics import TruePerson, longest_run, score_people


def test_the_cheapest_pairing_wins_over_the_greedy_one():
    # greedy would pair track 0 with observation 0 (0.1) and leave track 1 with 0.9; the optimum is 0.3 + 0.3
    cost = np.array([[0.1, 0.3], [0.3, 0.9]])
    result = assign(cost)
    assert sorted(result.pairs) == [(0, 1), (1, 0)]
    assert result.lone_tracks == () and result.lone_observations == ()


def test_pairs_beyond_the_gate_are_never_made():
    expected = np.array([[0.0, 0.0, 3.0], [1.0, 0.0, 3.0]])
    observed = np.array([[0.05, 0.0, 3.0], [3.0, 0.0, 3.0]])  # the second is 2 m from every track
    cost = pair_costs(expected, observed, [None, None], [None, None], appearance_m=0.5, gate_m=0.8)
    assert cost[0, 0] == pytest.approx(0.05)
    assert cost[1, 1] == NO_PAIR and cost[0, 1] == NO_PAIR
    result = assign(cost)
    assert result.pairs == ((0, 0),)
    assert result.lone_tracks == (1,) and result.lone_observations == (1,)


def test_appearance_decides_between_two_people_at_the_same_distance():
    rng = np.random.default_rng(0)
    red = np.zeros((20, 20, 3), np.uint8)
    red[..., 0] = 200 + rng.integers(0, 40, (20, 20))
    blue = np.zeros((20, 20, 3), np.uint8)
    blue[..., 2] = 200 + rng.integers(0, 40, (20, 20))
    mask = np.ones((20, 20), bool)
    look_red, look_blue = colour_histogram(red, mask), colour_histogram(blue, mask)
    assert look_red.sum() == pytest.approx(1.0)
    assert bhattacharyya(look_red, look_red) == pytest.approx(0.0, abs=1e-7)
    assert bhattacharyya(look_red, look_blue) == pytest.approx(1.0)
    # two tracks and two observations all at the same place: only colour tells them apart
    centres = np.zeros((2, 3))
    cost = pair_costs(centres, centres, [look_red, look_blue], [look_blue, look_red], 0.5, 0.8)
    assert sorted(assign(cost).pairs) == [(0, 1), (1, 0)]
    assert colour_histogram(None, mask) is None and colour_histogram(red, ~mask) is None


def test_no_tracks_or_no_observations_leave_everything_alone():
    assert assign(np.zeros((0, 3))).lone_observations == (0, 1, 2)
    assert assign(np.zeros((2, 0))).lone_tracks == (0, 1)


def test_people_scores_count_switches_misses_and_per_person_error_by_hand():
    joints = np.zeros((14, 3))
    a, b = joints + [0.0, 0.0, 3.0], joints + [1.0, 0.0, 3.0]
    truth = {f: [TruePerson(1, a), TruePerson(2, b)] for f in range(6)}
    tracked = {f: {0: a + 0.01, 1: b} for f in range(3)}
    tracked.update({f: {1: a, 0: b} for f in (3, 4)})  # the ids swap at frame 3: two switches
    tracked[5] = {0: b}  # person 1 missed on the last frame
    r = score_people(truth, tracked)
    # MOTA = 1 - (misses + false positives + switches) / true objects = 1 - (1 + 0 + 2) / 12
    assert r["mota"] == pytest.approx(0.75)
    assert r["id_switches"] == 2 and r["misses"] == 1 and r["false_positives"] == 0
    one = r["per_person"][1]
    # frames 0-2 off by 1 cm on every axis, frames 3-4 exact
    assert one["mpjpe_mm"] == pytest.approx(3 * 10 * np.sqrt(3) / 5)
    assert one["matched_frames"] == 5 and one["visible_frames"] == 6 and one["longest_lost_run"] == 1
    assert r["per_person"][2]["mpjpe_mm"] == pytest.approx(0.0)


def test_a_hidden_person_is_no_miss_and_a_far_body_is_no_match():
    joints = np.zeros((14, 3))
    truth = {0: [TruePerson(1, joints, visible=0.1)], 1: [TruePerson(1, joints)]}
    tracked = {1: {7: joints + [2.0, 0.0, 0.0]}}  # 2 m away: a false positive and a miss
    r = score_people(truth, tracked)
    assert r["misses"] == 1 and r["false_positives"] == 1 and r["matches"] == 0
    assert r["per_person"][1]["visible_frames"] == 1
    assert longest_run([True, True, False, True]) == 2 and longest_run([]) == 0


def test_a_body_following_a_hidden_person_is_no_false_positive():
    joints = np.zeros((14, 3))
    truth = {0: [TruePerson(1, joints, visible=0.1), TruePerson(2, joints + [1.0, 0.0, 0.0])]}
    tracked = {0: {5: joints + 0.02, 6: joints + [1.0, 0.0, 0.0]}}  # 5 follows the hidden person 1
    r = score_people(truth, tracked)
    assert r["false_positives"] == 0 and r["misses"] == 0 and r["matches"] == 1
    assert r["matched"] == {2: {0: 6}}
    assert score_people({0: [TruePerson(1, joints, visible=0.0)]}, {})["mota"] is None  # nobody to find



def test_the_gate_widens_with_the_frames_dropped_since_the_last_tracked_one():
    """Live, frames dropped between two tracked ones let a person move further: 1 m away after the
    next frame is another person, 1 m away 20 dropped frames later (0.8 + 20 x 0.05 m) the same one.
    Offline no frame is dropped: a gap (frames the source could not deliver) leaves the gate as it is."""
    from types import SimpleNamespace

    from swarmpose.people.people_tracker import DROPPED_GATE_M, GATE_M, PeopleTracker, Track

    people = [SimpleNamespace(segment=object())]
    moved = [np.array([1.0, 0.0, 3.0])]
    for dropped, live, paired in ((0, True, False), (20, True, True), (20, False, False)):
        tracker = PeopleTracker(lambda body_id: None)
        tracker.live = live
        tracker.tracks = [Track(0, None, np.array([0.0, 0.0, 3.0]), last_frame=10)]
        tracker._last_index = 10
        result = tracker._associate(11 + dropped, people, moved, [None])
        assert (result.pairs == ((0, 0),)) == paired, (dropped, GATE_M + DROPPED_GATE_M * dropped)


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (4, 1), (3, 3), (2, 5)])
def test_assignment_costs_what_scipys_solver_finds(shape):
    from scipy.optimize import linear_sum_assignment

    rng = np.random.default_rng(sum(shape))
    for _ in range(50):
        cost = rng.uniform(0.0, 2.0, shape).round(1)  # rounded: ties happen
        cost[rng.random(shape) < 0.3] = NO_PAIR
        got = assign(cost)
        rows, cols = linear_sum_assignment(cost)
        kept = [(r, c) for r, c in zip(rows, cols) if cost[r, c] < NO_PAIR]
        assert len(got.pairs) == len(kept)
        assert sum(cost[r, c] for r, c in got.pairs) == pytest.approx(sum(cost[r, c] for r, c in kept))
        assert len({r for r, _ in got.pairs}) == len(got.pairs) == len({c for _, c in got.pairs})
        assert sorted([r for r, _ in got.pairs] + list(got.lone_tracks)) == list(range(shape[0]))
