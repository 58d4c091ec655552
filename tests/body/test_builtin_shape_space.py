"""The built-in body's shape space: one tracking topology, following the exact body.

Oracle: the exact body of each shape (:func:`build_parametric_body`: SDF + marching cubes),
with Open3D's distance from the tracking body's vertices to its surface. Bounds are the
measured figures (mean 0.6-1.0 mm, 95th percentile 1.9-2.8 mm, max 7-61 mm: the max is a
vertex swallowed where primitives merge, e.g. the crotch at thick legs) plus margin.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import surface_distance

from swarmpose.body.builtin_shape_space import STATURE_RANGE, BuiltinSpace, slider_of, stature_of
from swarmpose.core.errors import ConfigError

# name: (stature m, torso, arms, legs)
SHAPES = {
    "short-broad-torso": (1.55, 1.3, 1.0, 1.0),
    "tall-thin-arms": (1.95, 1.0, 0.8, 1.0),
    "thick-legs": (1.75, 1.0, 1.0, 1.4),
    "slim": (1.75, 0.75, 0.75, 0.75),
}


def vector(stature: float, torso: float, arms: float, legs: float) -> np.ndarray:
    return np.array([slider_of(stature), torso, arms, legs])


@pytest.fixture(scope="module")
def space() -> BuiltinSpace:
    return BuiltinSpace("", 1500)


def test_the_height_slider_maps_onto_statures():
    assert stature_of(0.0) == pytest.approx(STATURE_RANGE[0]) and stature_of(1.0) == pytest.approx(STATURE_RANGE[1])
    assert stature_of(0.5) == pytest.approx(1.75) and slider_of(1.75) == pytest.approx(0.5)
    assert [round(stature_of(v), 3) for v in (0.2, 0.8)] == [1.57, 1.93]  # the fitter's sweep values
    with pytest.raises(ConfigError):
        slider_of(2.2)


def test_the_start_is_the_default_adult_and_its_tracking_body_the_decimated_start_body(space):
    assert space.kind == "builtin" and space.names == ("height", "torso", "arms", "legs")
    assert space.shape_spec(space.start) == "height=1.750,torso=1.000,arms=1.000,legs=1.000,sex=neutral"
    lod = space.tracking_body(space.start)
    reference = space.full_body(space.start).tracking_lod(1500)
    np.testing.assert_allclose(lod.vertices, reference.vertices, atol=1e-12)
    np.testing.assert_allclose(lod.point_rest, reference.point_rest, atol=1e-12)


def test_tracking_bodies_share_one_topology(space):
    reference = space.tracking_body(space.start)
    for shape in [*SHAPES.values(), (2.05, 1.5, 1.5, 1.5), (1.45, 0.7, 0.7, 0.7)]:
        body = space.tracking_body(vector(*shape))
        assert body.vertices.shape == reference.vertices.shape
        assert np.array_equal(body.triangles, reference.triangles)
        assert np.array_equal(body.skin_indices, reference.skin_indices)
        assert np.array_equal(body.skin_weights, reference.skin_weights)
        assert body.bone_names == reference.bone_names and np.array_equal(body.bone_parents, reference.bone_parents)
        assert body.point_names == reference.point_names
        assert np.array_equal(body.point_bones, reference.point_bones)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_tracking_bodies_follow_the_exact_surface(space, name):
    x = vector(*SHAPES[name])
    lod, full = space.tracking_body(x), space.full_body(x)
    d = surface_distance(full.vertices, full.triangles, lod.vertices)
    assert d.mean() < 0.002 and np.percentile(d, 95) < 0.005 and d.max() < 0.075, (name, d.mean(), d.max())
    assert abs(lod.height - full.height) < 0.01
    np.testing.assert_allclose(lod.bone_heads, full.bone_heads, atol=1e-9)  # shoulders move out with the torso
    np.testing.assert_allclose(lod.bind_matrices, full.bind_matrices, atol=1e-9)
    joints = [i for i, n in enumerate(lod.point_names) if n not in ("nose", "left_ear", "right_ear")]
    np.testing.assert_allclose(lod.point_rest[joints], full.point_rest[joints], atol=0.005)  # toes, heels: mesh picks
    np.testing.assert_allclose(lod.point_rest, full.point_rest, atol=0.015)  # nose, ears: picked from the mesh


@pytest.mark.slow
def test_the_largest_shape_stays_close_on_average(space):
    x = vector(2.05, 1.5, 1.5, 1.5)
    lod, full = space.tracking_body(x), space.full_body(x)
    d = surface_distance(full.vertices, full.triangles, lod.vertices)
    assert d.mean() < 0.0035 and np.percentile(d, 95) < 0.01, (d.mean(), np.percentile(d, 95))


def test_a_shape_spec_loads_as_the_body_of_that_stature(space):
    from swarmpose.body.loader import load_body

    x = np.array([slider_of(1.812), 1.05, 0.97, 1.01])
    spec = space.shape_spec(x)
    assert spec == "height=1.812,torso=1.050,arms=0.970,legs=1.010,sex=neutral"
    body = load_body("builtin", spec)
    assert abs(body.height - 1.812) < 0.01
    assert abs(space.tracking_body(x).height - 1.812) < 0.01
    np.testing.assert_array_equal(body.vertices, space.full_body(x).vertices)


def test_parameters_outside_the_bounds_are_clipped(space):
    wild = np.array([1.7, 0.2, 3.0, -1.0])
    edge = np.array([1.0, 0.7, 1.5, 0.7])
    assert space.parameters(wild) == space.parameters(edge) == {"height": 1.0, "torso": 0.7, "arms": 1.5, "legs": 0.7}
    assert space.shape_spec(wild) == "height=2.050,torso=0.700,arms=1.500,legs=0.700,sex=neutral"
    np.testing.assert_array_equal(space.tracking_body(wild).vertices, space.tracking_body(edge).vertices)
    with pytest.raises(ConfigError):
        space.tracking_body([0.5, 1.0, 1.0])
    with pytest.raises(ConfigError):
        space.shape_spec([np.nan, 1.0, 1.0, 1.0])


def test_the_sex_comes_from_the_shape_spec():
    from swarmpose.body.shape_space import shape_space_for

    space = shape_space_for("builtin", "female-short", 1500)
    assert isinstance(space, BuiltinSpace) and space.body_spec() == "builtin"
    assert space.shape_spec(space.start).endswith("sex=female")
    assert space.full_body(space.start).metadata["shape"]["sex"] == "female"
    with pytest.raises(ConfigError):
        BuiltinSpace("sex=robot")
