"""A body's remembered single-pose transforms: always those forward kinematics gives, never editable."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.kinematics import skinning_transforms
from swarmpose.body.loader import load_body
from swarmpose.body.skinned import POSE_MEMO


def _poses(n: int) -> np.ndarray:
    body = load_body("builtin")
    h = np.repeat(body.rest_pose((0.0, 0.0, 3.0))[None], n, axis=0)
    h[:, 7:] += np.random.default_rng(3).normal(0.0, 0.3, (n, h.shape[1] - 7))
    return h


def test_a_pose_posed_again_gets_the_transforms_forward_kinematics_gives():
    body = load_body("builtin")
    h = _poses(POSE_MEMO + 5)
    order = [0, 1, 0, 2, 1, *range(3, len(h)), 0, 1]  # repeats, then more poses than the memo holds, then repeats
    for k in order:
        got = body.transforms(h[k])
        assert got.shape == (1, len(body.bone_names), 3, 4)
        np.testing.assert_array_equal(got, skinning_transforms(body.rig, h[k][None]))


def test_a_batch_and_a_single_pose_agree_and_neither_can_be_edited():
    body = load_body("builtin")
    h = _poses(3)
    batch = body.transforms(h)
    for k in range(3):
        np.testing.assert_array_equal(body.transforms(h[k:k + 1])[0], batch[k])
    for out in (batch, body.transforms(h[0])):
        with pytest.raises(ValueError):
            out[0, 0, 0, 0] = 1.0  # a caller that edited a remembered result would corrupt the next one


def test_a_pose_changed_in_place_after_posing_is_posed_anew():
    body = load_body("builtin")
    h = _poses(1)[0]
    first = body.transforms(h).copy()
    h[10] += 0.5  # the caller reuses its array
    np.testing.assert_array_equal(body.transforms(h), skinning_transforms(body.rig, h[None]))
    assert not np.array_equal(body.transforms(h), first)
