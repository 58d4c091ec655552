"""MakeHuman's macro sliders and the shape space personalisation searches.

Oracles: the assets README's preset recipes (PRESETS), MakeHuman's slider rule worked by hand,
and Open3D's distance to the full-resolution mesh for the tracking bodies."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MAKEHUMAN, needs_assets, surface_distance

from swarmpose.body.makehuman_macros import PRESET_MACROS, MacroShape, parse_macros, slider_factors
from swarmpose.core.errors import ConfigError


@pytest.mark.parametrize("value, expected", [(0.0, (1, 0, 0)), (0.25, (0.5, 0.5, 0)), (0.5, (0, 1, 0)),
                                             (0.75, (0, 0.5, 0.5)), (1.0, (0, 0, 1))])
def test_a_slider_splits_over_its_two_nearest_targets(value, expected):
    got = slider_factors(value)
    assert (got["min"], got["average"], got["max"]) == pytest.approx(expected)


def test_sliders_weigh_combined_targets_by_the_product_of_their_factors():
    recipe = MacroShape(gender=0.25, caucasian=1.0, muscle=0.75, weight=0.25, height=0.5).recipe()
    # female 0.75, male 0.25; muscle average .5 / max .5; weight min .5 / average .5
    assert recipe["caucasian-female-young"] == pytest.approx(0.75)
    assert recipe["universal-female-young-maxmuscle-minweight"] == pytest.approx(0.75 * 0.5 * 0.5)
    assert recipe["universal-male-young-averagemuscle-minweight"] == pytest.approx(0.25 * 0.5 * 0.5)
    assert not any("height" in k for k in recipe)  # height 0.5: neither height target


def test_macro_specs_are_checked():
    assert parse_macros("female,weight=0.8") == MacroShape(gender=0.0, weight=0.8)
    for bad in ("gender=1.5", "shoe=1", "weight=heavy", "giant,height=1"):
        with pytest.raises(ConfigError):
            parse_macros(bad)


@needs_assets
@pytest.mark.parametrize("preset", sorted(PRESET_MACROS))
def test_every_preset_is_a_point_of_the_slider_space(preset):
    from swarmpose.body.makehuman import PRESETS, shaped_vertices

    readme = shaped_vertices(MAKEHUMAN, PRESETS[preset])
    sliders = shaped_vertices(MAKEHUMAN, PRESET_MACROS[preset].recipe())
    np.testing.assert_allclose(sliders, readme, atol=1e-9)


@needs_assets
def test_a_slider_shape_loads_as_a_body_spec():
    from swarmpose.body.loader import load_body

    preset = load_body(f"makehuman:{MAKEHUMAN}", "female-tall")
    sliders = load_body(f"makehuman:{MAKEHUMAN}", "gender=0,height=0.625")
    np.testing.assert_allclose(sliders.vertices, preset.vertices, atol=1e-9)
    assert sliders.metadata["macros"]["height"] == 0.625


@needs_assets
def test_tracking_bodies_keep_one_topology_and_follow_the_full_surface():
    from swarmpose.body.loader import load_body
    from swarmpose.body.shape_space import MakeHumanSpace

    space = MakeHumanSpace(MAKEHUMAN)
    reference = space.tracking_body(space.start)
    for name in ("female-short", "male-heavy", "male-tall"):
        x = PRESET_MACROS[name].vector()
        lod, full = space.tracking_body(x), space.full_body(x)
        assert lod.triangles.shape == reference.triangles.shape and np.array_equal(lod.triangles, reference.triangles)
        d = surface_distance(full.vertices, full.triangles, lod.vertices)
        assert d.mean() < 0.002 and d.max() < 0.012, (name, d.mean(), d.max())
        np.testing.assert_allclose(lod.bone_heads, full.bone_heads)
        # and the rig is the preset's own, loaded the ordinary way (an oracle apart from the space)
        np.testing.assert_allclose(lod.bone_heads, load_body(f"makehuman:{MAKEHUMAN}", name).bone_heads, atol=1e-6)
        assert abs(lod.height - full.height) < 0.01


def test_a_fixed_body_has_no_shape_space(tmp_path):
    from swarmpose.body.builtin_shape_space import BuiltinSpace
    from swarmpose.body.shape_space import shape_space_for

    with pytest.raises(ConfigError, match="makehuman:DIR"):
        shape_space_for(str(tmp_path / "someone.glb"))
    assert isinstance(shape_space_for("builtin"), BuiltinSpace)
