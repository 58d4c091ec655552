"""The local polish (pose_polish) on an objective whose minimum is known in closed form."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import ANGLE_NAMES
from swarmpose.tracking.pose_polish import WITHOUT_ARMS, polish_pose
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
