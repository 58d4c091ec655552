"""The local polish (pose_polish) on an objective whose minimum is known in closed form."""

from __future__ import annotations

import numpy as np

from swarmpose.body.kinematics import quaternion_multiply, root_turn_deg
from swarmpose.body.skeleton import ANGLE_NAMES
from swarmpose.tracking.pose_polish import WITHOUT_ARMS, polish_facings, polish_pose, polish_solution
from swarmpose.tracking.pso import PsoResult
from swarmpose.tracking.search import pose_bounds


def bowl(target: np.ndarray, scale: np.ndarray):
    """A separable quadratic (P, 36) -> (P,) with its minimum 0 at ``target``, and a call counter."""
    calls = []

    def objective(poses: np.ndarray) -> np.ndarray:
        calls.append(len(poses))
        return (((poses - target) / scale) ** 2).sum(axis=1)

    return objective, calls


def a_pose(rng: np.random.Generator) -> np.ndarray:
    """A pose (36,) inside the angle limits with a unit root quaternion."""
    lo, hi = pose_bounds()
    pose = np.zeros(36)
    pose[:3] = (0.1, -0.2, 3.0)
    q = rng.normal(size=4)
    pose[3:7] = q / np.linalg.norm(q)
    pose[7:] = lo[7:] + rng.uniform(0.3, 0.7, 29) * (hi[7:] - lo[7:])
    return pose


def test_the_polish_walks_down_a_known_bowl_and_never_up():
    rng = np.random.default_rng(5)
    target = a_pose(rng)
    start = target.copy()
    start[:3] += (0.03, -0.02, 0.04)
    start[7:] += rng.normal(0.0, 0.08, 29)
    start[7:] = np.clip(start[7:], *[b[7:] for b in pose_bounds()])
    scale = np.full(36, 0.05)
    scale[:3] = 0.01
    objective, calls = bowl(target, scale)
    before = float(objective(start[None])[0])
    calls.clear()
    best, value = polish_pose(objective, start, 200, np.random.default_rng(0))
    assert calls == [1] + [32] * 200  # the start, then one batch of 32 a round
    assert np.isclose(value, objective(best[None])[0])  # the value is the returned pose's
    assert value < 0.1 * before, (value, before)
    lo, hi = pose_bounds()
    assert np.all(best >= lo) and np.all(best <= hi)
    assert np.isclose(np.linalg.norm(best[3:7]), 1.0)


def test_coordinates_not_movable_stay_exactly_and_no_rounds_change_nothing():
    rng = np.random.default_rng(6)
    target = a_pose(rng)
    start = np.clip(target + np.r_[np.zeros(7), rng.normal(0.0, 0.1, 29)], *pose_bounds())
    objective, _ = bowl(target, np.full(36, 0.05))
    best, value = polish_pose(objective, start, 80, np.random.default_rng(1), WITHOUT_ARMS)
    arms = [7 + k for k, name in enumerate(ANGLE_NAMES)  # the arms' angles by their names: 12 of them
            if name.split(".")[0] in {f"{s}_{j}" for s in ("left", "right") for j in ("collar", "shoulder", "elbow")}]
    assert len(arms) == 12 and np.flatnonzero(~WITHOUT_ARMS).tolist() == arms
    assert np.array_equal(best[arms], start[arms])
    assert value < objective(start[None])[0]
    assert np.any(best[WITHOUT_ARMS] != start[WITHOUT_ARMS])
    counted, calls = bowl(target, np.full(36, 0.05))
    same, nothing = polish_pose(counted, start, 0, np.random.default_rng(1))
    assert np.array_equal(same, start) and np.isnan(nothing) and calls == []


def test_a_minimum_beyond_the_angle_limits_is_met_at_the_limits_and_non_finite_values_never_win():
    rng = np.random.default_rng(7)
    lo, hi = pose_bounds()
    start = a_pose(rng)
    target = start.copy()
    target[7:] = hi[7:] + 0.5  # every angle's minimum lies past its upper limit
    bowl_of, _ = bowl(target, np.full(36, 0.05))

    def objective(poses: np.ndarray) -> np.ndarray:  # NaN for a third of the copies, and at the start
        values = bowl_of(poses)
        values[::3] = np.nan
        return values

    best, value = polish_pose(objective, start, 150, np.random.default_rng(2))
    assert np.isfinite(value) and np.isclose(value, bowl_of(best[None])[0])
    assert np.all(best[7:] <= hi[7:]) and np.all(best[7:] >= lo[7:])
    assert np.mean(hi[7:] - best[7:]) < 0.25 * np.mean(hi[7:] - start[7:])  # pressed towards the limits


def _two_facings(rng: np.random.Generator):
    """A track's pose, an objective with a basin of its facing (floor 1.0) and a deeper one of the
    pose turned by 180 degrees about the vertical (floor 0.5), and a search result whose best
    particle lies near the shallow basin's floor (1.01) while the turned one starts higher (1.5)."""
    track = a_pose(rng)
    turned = track.copy()
    turned[3:7] = quaternion_multiply(track[3:7], np.array([0.0, 0.0, 1.0, 0.0]))  # 180 deg about body y
    own_target, turned_target = track[7:].copy(), np.clip(track[7:] + 0.1, *[b[7:] for b in pose_bounds()])

    def objective(poses: np.ndarray) -> np.ndarray:
        is_turned = root_turn_deg(track, poses) > 90.0
        target = np.where(is_turned[:, None], turned_target, own_target)
        return np.where(is_turned, 0.5, 1.0) + ((poses[:, 7:] - target) ** 2).sum(axis=1)

    own = track.copy()
    own[7:] += 0.1 / np.sqrt(29)  # 1.01
    other = turned.copy()
    other[7:] = turned_target + 1.0 / np.sqrt(29) * np.sign(rng.normal(size=29))  # 1.5
    other[7:] = np.clip(other[7:], *[b[7:] for b in pose_bounds()])
    poses = np.stack([own, other, own + 0.001])
    values = objective(poses)
    result = PsoResult(own.copy(), float(values[0]), values[:1], 3, poses, values)
    return track, objective, result


def test_each_facing_is_polished_before_they_compete():
    """The turned particle, worse as the search left it (1.5 against 1.01), wins once both are
    polished (its basin is 0.5 deep): the two facings compete at their own minima."""
    track, objective, result = _two_facings(np.random.default_rng(2))
    assert result.personal_values[1] > result.value
    out = polish_facings(objective, result, track, 60, np.random.default_rng(0))
    assert root_turn_deg(track, out.best) > 90.0, "the deeper, turned basin should win after the polish"
    assert out.value < 1.0 and np.isclose(out.value, objective(out.best[None])[0])
    assert np.all(out.personal_values <= result.personal_values)  # never worse, for either facing
    assert polish_facings(objective, result, track, 0, np.random.default_rng(0)) is result  # 0 rounds: as it is


def test_with_one_facing_in_the_swarm_only_the_best_is_polished_as_before():
    """No turned particle: exactly the polish of the search's best (same draws, same pose)."""
    track, objective, result = _two_facings(np.random.default_rng(3))
    same = PsoResult(result.best, result.value, result.history, 3, result.personal_bests[[0, 2]],
                     result.personal_values[[0, 2]])
    out = polish_facings(objective, same, track, 40, np.random.default_rng(7), WITHOUT_ARMS)
    want, value = polish_pose(objective, result.best, 40, np.random.default_rng(7), WITHOUT_ARMS)
    np.testing.assert_array_equal(out.best, want)
    assert out.value == value


def test_a_young_track_duels_a_settled_one_keeps_its_choice():
    """polish_solution: with the duel (a young track) the turned facing, polished, wins; without it
    the tracker's choice (here: the search's best, the track's facing) is polished alone and kept;
    on a track's first frame (no previous pose) the search's best is polished."""
    track, objective, result = _two_facings(np.random.default_rng(2))
    chosen = []

    def hold(res: PsoResult) -> np.ndarray:
        chosen.append(res.best.copy())
        return res.best

    young = polish_solution(objective, result, track, 60, np.random.default_rng(0), True, hold)
    assert root_turn_deg(track, young) > 90.0
    settled = polish_solution(objective, result, track, 60, np.random.default_rng(0), False, hold)
    assert root_turn_deg(track, settled) < 90.0 and np.array_equal(chosen[-1], result.best)
    assert objective(settled[None])[0] <= result.value
    first = polish_solution(objective, result, None, 60, np.random.default_rng(0), True, hold)
    np.testing.assert_array_equal(first, polish_pose(objective, result.best, 60, np.random.default_rng(0),
                                                     WITHOUT_ARMS)[0])
