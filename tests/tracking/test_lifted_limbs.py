"""Live frames' limb seeds: the base pose's limbs solved to the frame's lifted joints."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.tracking.lifted_limbs import FAR_M, lifted_limb_seeds, lifted_targets
from swarmpose.tracking.limb_flips import FLIP_LIMBS, limb_columns
from swarmpose.tracking.objective import JointTargets

NAMES = ("left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
         "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


def targets_of(body, pose: np.ndarray, missing: tuple[str, ...] = ()) -> JointTargets:
    """Targets whose lifts are ``pose``'s own points (NaN for ``missing``)."""
    xyz = body.posed_points(pose[None], NAMES)[0]
    xyz[[NAMES.index(n) for n in missing]] = np.nan
    return JointTargets(NAMES, body.point_indices(NAMES), np.zeros((len(NAMES), 2)), xyz, np.ones(len(NAMES)))


def moved(body, pose: np.ndarray, limb: tuple[str, str, str], by: float) -> np.ndarray:
    out = pose.copy()
    out[limb_columns(limb)[:3]] += by  # the pivot's three angles
    return out


def test_limbs_far_from_their_lifts_are_solved_to_them_and_the_rest_left(body):
    truth = body.rest_pose((0.1, 0.0, 3.0))
    left_arm, right_leg = FLIP_LIMBS[0], FLIP_LIMBS[3]
    assert left_arm[0] == "left_shoulder" and right_leg[0] == "right_hip"
    base = moved(body, moved(body, truth, left_arm, 0.45), right_leg, -0.3)
    base[limb_columns(FLIP_LIMBS[2])] += 0.01  # the right arm a hair off: within FAR_M, left as it is
    (seed,) = lifted_limb_seeds(body, [base], targets_of(body, truth))
    ends = ("left_elbow", "left_wrist", "right_knee", "right_ankle")
    before = np.linalg.norm(body.posed_points(base[None], ends)[0] - body.posed_points(truth[None], ends)[0], axis=1)
    after = np.linalg.norm(body.posed_points(seed[None], ends)[0] - body.posed_points(truth[None], ends)[0], axis=1)
    assert np.all(before > FAR_M) and np.all(after < 0.03), (before, after)
    untouched = np.ones(36, bool)
    untouched[np.r_[limb_columns(left_arm), limb_columns(right_leg)]] = False
    np.testing.assert_array_equal(seed[untouched], base[untouched])  # the torso, the right arm, the left leg


def test_a_limb_without_both_lifts_is_not_solved_and_none_far_gives_no_seed(body):
    truth = body.rest_pose((0.0, 0.0, 3.0))
    base = moved(body, truth, FLIP_LIMBS[0], 0.45)
    targets = targets_of(body, truth, missing=("left_wrist",))
    assert FLIP_LIMBS[0] not in lifted_targets(targets)[0]
    assert lifted_limb_seeds(body, [base], targets) == []
    assert lifted_limb_seeds(body, [truth], targets_of(body, truth)) == []  # every limb at its lifts


def test_each_base_gets_its_own_seed(body):
    truth = body.rest_pose((0.0, 0.0, 3.0))
    near = moved(body, truth, FLIP_LIMBS[0], 0.45)
    shifted = near.copy()
    shifted[0] += 0.05  # the torso 5 cm to the side
    seeds = lifted_limb_seeds(body, [near, shifted], targets_of(body, truth))
    assert len(seeds) == 2
    assert seeds[1][0] == pytest.approx(shifted[0]) and seeds[0][0] == pytest.approx(near[0])
