"""The shape fit's last stage: the compass search against hand-computed paths, and the own-pose
energy against the oracle of a synthetic subject's true shape."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import MAKEHUMAN, makehuman_walk, needs_assets

from swarmpose.personalise.own_pose_search import compass_search


def _counting(f):
    calls = []

    def energy(x):
        calls.append(np.array(x, float))
        return f(np.asarray(x, float))
    return energy, calls


def test_the_compass_search_walks_a_quadratic_to_its_minimum_within_the_least_step():
    target = np.array([0.3, 0.7])
    energy, calls = _counting(lambda x: float(np.sum((x - target) ** 2)))
    x, value, judged = compass_search(energy, np.array([0.9, 0.1]), np.zeros(2), np.ones(2), 0.15, 0.01, 1000)
    # steps 0.15, 0.075, 0.0375, 0.01875: 0.9 -> 0.3 in four moves of 0.15, 0.1 -> 0.7 likewise
    np.testing.assert_allclose(x, target, atol=0.01)
    assert value == pytest.approx(float(np.sum((x - target) ** 2)))
    assert judged % 4 == 0  # whole rounds of 2 x 2 candidates
    # a move's starting point (and any other point seen before) comes back as a candidate: never judged twice
    assert len({tuple(np.round(c, 9)) for c in calls}) == len(calls) < 1 + judged - 8


def test_the_compass_search_stays_in_the_box_and_scales_its_step_by_each_range():
    energy, calls = _counting(lambda x: float((x[0] - 5.0) ** 2 + (x[1] + 3.0) ** 2))  # the minimum lies outside
    lower, upper = np.array([0.0, -1.0]), np.array([1.0, 3.0])
    x, _, _ = compass_search(energy, np.array([0.5, 1.0]), lower, upper, 0.25, 0.05, 1000)
    np.testing.assert_allclose(x, [1.0, -1.0])  # the corner nearest the minimum
    assert all(np.all(c >= lower) and np.all(c <= upper) for c in calls)
    # the first round moves each parameter by 0.25 of its own range: 0.25 and 1.0
    first = np.array(calls[1:5])
    np.testing.assert_allclose(first, [[0.25, 1.0], [0.75, 1.0], [0.5, 0.0], [0.5, 2.0]])


def test_the_compass_search_skips_the_moves_the_box_cancels():
    energy, calls = _counting(lambda x: 0.0)
    _, _, judged = compass_search(energy, np.zeros(3), np.zeros(3), np.ones(3), 0.15, 0.1, 1000)
    assert judged == 3  # from the corner only the three moves inward, then 0.075 < 0.1 stops it
    np.testing.assert_allclose(np.array(calls[1:]), 0.15 * np.eye(3))


def test_the_compass_search_halves_its_step_until_the_least_and_keeps_its_budget():
    energy, calls = _counting(lambda x: 0.0)  # nothing ever improves
    x, _, judged = compass_search(energy, np.array([0.5, 0.5, 0.5]), np.zeros(3), np.ones(3), 0.15, 0.04, 1000)
    assert judged == 12 and len(calls) == 13  # 0.15 and 0.075 judged (6 candidates each), 0.0375 < 0.04
    np.testing.assert_allclose(x, 0.5)
    energy, calls = _counting(lambda x: -float(np.sum(x)))  # always improves: only the budget stops it
    _, _, judged = compass_search(energy, np.full(3, 50.0), np.zeros(3), np.full(3, 100.0), 0.01, 0.001, 10)
    assert judged == 12  # two rounds of 6: the budget is checked before each round


@pytest.fixture(scope="module")
def female_walk(tmp_path_factory):
    return makehuman_walk(tmp_path_factory, "female", 12)


@pytest.mark.slow
@needs_assets
@pytest.mark.parametrize("wrong", ["female-muscular", "female-slim"])
def test_with_poses_of_its_own_the_true_shape_beats_the_shape_the_poses_were_tracked_with(female_walk, wrong):
    """Poses tracked with a wrong body favour it when held (female-muscular: the held energy ranks
    it below the subject's own shape); polished for each body, the true shape wins, by more than it
    does with the poses held, and the energy repeats to the digit (common random numbers)."""
    from swarmpose.body.makehuman_macros import PRESET_MACROS
    from swarmpose.body.shape_space import shape_space_for
    from swarmpose.detect.simulated import SimulatedDetector
    from swarmpose.gpu.context import ClContext
    from swarmpose.personalise.own_pose_search import own_pose_energy
    from swarmpose.personalise.personalise import ShapeSample, _KeyFrame
    from swarmpose.sources.folder import FolderSource
    from swarmpose.sources.groundtruth import load_ground_truth
    from swarmpose.tracking.body_tracker import BodyTracker
    from swarmpose.tracking.config import TrackerConfig

    space = shape_space_for(f"makehuman:{MAKEHUMAN}", None, 1500)
    true_x, wrong_x = PRESET_MACROS["female"].vector(), PRESET_MACROS[wrong].vector()
    source = FolderSource(female_walk)
    detector = SimulatedDetector(load_ground_truth(female_walk))
    config = replace(TrackerConfig(), particles=24, generations=24, coarse_share=0.0, limb_flips=False,
                     limb_exchanges=False, polish=0)
    context = ClContext.for_spec(config.device)
    tracker = BodyTracker(space.tracking_body(wrong_x), source.intrinsics, replace(config, polish=60), context)
    samples = []
    for frame in source:
        joints = detector.detect(frame)
        samples.append(ShapeSample(frame, joints, np.asarray(tracker.step(frame, joints).pose, float)))
    wrong_body = space.fitting_body(wrong_x)
    keys = [_KeyFrame(s, wrong_body, source.intrinsics, config, (96, 96), context, tracker) for s in samples[::2]]
    starts = [k.pose for k in keys]
    bodies = {"true": space.fitting_body(true_x), "wrong": wrong_body}
    held = {name: np.mean([k.energy(body) for k in keys]) for name, body in bodies.items()}
    own = {name: own_pose_energy(keys, starts, body, 60) for name, body in bodies.items()}
    assert own["true"] < own["wrong"], own
    assert own["wrong"] - own["true"] > held["wrong"] - held["true"], (own, held)
    assert own_pose_energy(keys, starts, bodies["true"], 60) == own["true"]
