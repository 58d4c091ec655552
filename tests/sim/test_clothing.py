"""Clothes for the synthetic renders: garments by bone, and the render's colours where the body's
own points project (the Lambert shade scales a pixel's albedo, so its channel ratios are the
garment's)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.sim.clothing import SHOE_ALBEDO, SKIN_ALBEDOS, TROUSER_ALBEDOS, bone_garments, clothing_albedo
from swarmpose.sim.render import Renderer
from tests.conftest import MAKEHUMAN, needs_assets

INTR = Intrinsics(320, 240, 285.0, 285.0, 159.5, 119.5)
SHIRT = np.array([0.2, 0.55, 0.6])


def _garment_of(body, bone: str) -> str:
    return bone_garments(body)[body.bone_names.index(bone)]


def test_builtin_bones_wear_what_a_short_sleeved_person_wears():
    body = load_body("builtin")
    expected = {"head": "skin", "neck": "skin", "left_forearm": "skin", "right_hand": "skin",
                "spine_upper": "shirt", "left_clavicle": "shirt", "right_upper_arm": "shirt",
                "pelvis": "trousers", "left_thigh": "trousers", "right_shin": "trousers",
                "left_foot": "shoes", "right_foot": "shoes"}
    assert {bone: _garment_of(body, bone) for bone in expected} == expected


@needs_assets
def test_makehuman_bones_wear_the_same_through_the_cmu_rig():
    body = load_body(f"makehuman:{MAKEHUMAN}", "female")
    expected = {"Head": "skin", "LeftHand": "skin", "RightHandFinger1": "skin", "LeftForeArm": "skin",
                "Spine1": "shirt", "RightArm": "shirt", "Hips": "trousers", "LHipJoint": "trousers",
                "RightLeg": "trousers", "LeftToeBase": "shoes"}
    assert {bone: _garment_of(body, bone) for bone in expected} == expected


def _chroma(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb, float)
    return rgb / rgb.sum()


@pytest.mark.parametrize("point, garment", [("left_wrist", "skin"), ("nose", "skin"), ("left_knee", "trousers"),
                                            ("left_shoulder", "shirt"), ("right_toe", "shoes")])
def test_a_dressed_render_shows_each_garment_where_its_body_part_projects(point, garment):
    body = load_body("builtin")
    pose = np.zeros(36)
    pose[2], pose[4] = 2.5, 1.0  # 2.5 m in front, turned 180 degrees about x: upright in the image
    pose[7:] = body.rest_angles
    verts = body.pose(pose[None])[0]
    albedo = clothing_albedo(body, SHIRT, 0)
    _, colour, labels = Renderer(INTR).render_people([(verts, body.triangles)], albedos=[albedo])
    u, v = np.round(INTR.project(body.posed_points(pose[None], [point])[0])[0]).astype(int)
    assert labels[v, u] == 1
    want = {"skin": SKIN_ALBEDOS[0], "shirt": SHIRT, "trousers": TROUSER_ALBEDOS[0], "shoes": SHOE_ALBEDO}[garment]
    others = [a for g, a in {"skin": SKIN_ALBEDOS[0], "shirt": SHIRT, "trousers": TROUSER_ALBEDOS[0]}.items()
              if g != garment]
    seen = _chroma(colour[v, u].astype(float) + 0.5)  # uint8 rounding
    assert np.abs(seen - _chroma(want)).max() < 0.03
    assert all(np.abs(seen - _chroma(a)).max() > 0.05 for a in others)


def test_synth_dresses_only_when_asked_and_says_so(tmp_path):
    from swarmpose.cli.main import main

    for name, flag in (("plain", []), ("dressed", ["--clothes"])):
        assert main(["synth", "--motion", "builtin:wave", "--frames", "1", "--out", str(tmp_path / name), "-q",
                     *flag]) == 0
    import cv2

    plain, dressed = (cv2.imread(str(tmp_path / n / "color" / "000000.png")) for n in ("plain", "dressed"))
    depth = [cv2.imread(str(tmp_path / n / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED) for n in ("plain", "dressed")]
    np.testing.assert_array_equal(depth[0], depth[1])  # the depth is the same
    assert np.any(plain != dressed)
    meta = [json.loads((tmp_path / n / "sequence.json").read_text()) for n in ("plain", "dressed")]
    assert [m["clothes"] for m in meta] == [False, True]
