"""A scorer given another shape scores as a scorer built for that shape (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MAKEHUMAN, needs_assets

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ShapeError
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around

INTR = Intrinsics(320, 240, 280.0, 280.0, 160.0, 120.0)


@needs_assets
def test_set_body_scores_as_a_fresh_scorer_of_that_shape():
    from swarmpose.body.makehuman_macros import PRESET_MACROS
    from swarmpose.body.shape_space import MakeHumanSpace

    space = MakeHumanSpace(MAKEHUMAN)
    slim, heavy = (space.tracking_body(PRESET_MACROS[n].vector()) for n in ("female-slim", "male-heavy"))
    facing = (0.0, 0.0, 1.0, 0.0)
    rng = np.random.default_rng(3)
    poses = np.tile(heavy.rest_pose((0.0, 0.1, 3.0), facing), (6, 1))
    poses[:, 7:] += rng.normal(0.0, 0.2, (6, 29))
    observed_body = heavy.pose(poses[:1])[0]
    depth = np.zeros((INTR.height, INTR.width), np.float32)
    uv = np.round(INTR.project(observed_body)).astype(int)
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < INTR.width) & (uv[:, 1] >= 0) & (uv[:, 1] < INTR.height)
    depth[uv[ok, 1], uv[ok, 0]] = observed_body[ok, 2]
    box = box_around(INTR.project(observed_body), margin=0.1)

    moved = ParticleScorer(slim, INTR, (48, 48), context="cpu")
    moved.set_observation(depth, box)
    before, _ = moved.score(poses)
    moved.set_body(heavy)
    fresh = ParticleScorer(heavy, INTR, (48, 48), context="cpu")
    fresh.set_observation(depth, box)
    got, got_counts = moved.score(poses)
    want, want_counts = fresh.score(poses)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    for name in want_counts:
        np.testing.assert_array_equal(got_counts[name], want_counts[name])
    assert not np.allclose(before, want)  # the shapes really score differently


@needs_assets
def test_set_body_refuses_another_topology():
    from swarmpose.body.loader import load_body

    body = load_body(f"makehuman:{MAKEHUMAN}", "male").tracking_lod(1500)
    scorer = ParticleScorer(body, INTR, (32, 32), context="cpu")
    with pytest.raises(ShapeError, match="topology"):
        scorer.set_body(load_body(f"makehuman:{MAKEHUMAN}", "male").tracking_lod(800))
