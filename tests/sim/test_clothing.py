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


def _upright(body, x: float = 0.0, z: float = 2.5) -> np.ndarray:
    """A pose (36,) of ``body`` at rest, ``x`` m to the side and ``z`` m in front of the camera,
    turned 180 degrees about the camera's x axis: upright in the image (y down)."""
    pose = np.zeros(36)
    pose[0], pose[2], pose[4] = x, z, 1.0
    pose[7:] = body.rest_angles
    return pose


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
    pose = _upright(body)
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


def test_a_second_dressed_person_beside_the_room_wears_their_own_clothes():
    """Per-triangle albedos index each mesh's own triangles (Open3D's primitive ids count within a
    geometry): person 2, cast after person 1 and before the room, shows its own garments."""
    from swarmpose.sim.render import Room

    body = load_body("builtin")
    poses = np.stack([_upright(body, -0.5, 3.0), _upright(body, 0.5, 3.0)])
    verts = body.pose(poses)
    room = Room(np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 5.0]),
                np.array([0.0, 0.0, -1.0]))
    shirt = np.array([0.8, 0.3, 0.3])
    albedos = [clothing_albedo(body, SHIRT, 0), clothing_albedo(body, shirt, 1)]
    _, colour, labels = Renderer(INTR).render_people([(verts[0], body.triangles), (verts[1], body.triangles)], room,
                                                     albedos)
    for point, want in (("left_shoulder", shirt), ("left_knee", TROUSER_ALBEDOS[1]), ("nose", SKIN_ALBEDOS[1])):
        u, v = np.round(INTR.project(body.posed_points(poses[1:], [point])[0])[0]).astype(int)
        assert labels[v, u] == 2
        assert np.abs(_chroma(colour[v, u].astype(float) + 0.5) - _chroma(want)).max() < 0.03


def test_one_albedo_per_triangle_all_alike_is_the_plain_render_and_a_wrong_count_is_refused():
    from swarmpose.core.errors import ShapeError
    from swarmpose.sim.render import person_albedo

    body = load_body("builtin")
    mesh = (body.pose(_upright(body)[None])[0], body.triangles)
    renderer = Renderer(INTR)
    plain = renderer.render_people([mesh])
    tiled = renderer.render_people([mesh], albedos=[np.tile(person_albedo(0), (len(body.triangles), 1))])
    for a, b in zip(plain, tiled):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ShapeError, match="person 1"):
        renderer.render_people([mesh], albedos=[np.tile(person_albedo(0), (len(body.triangles) - 1, 1))])


def test_synth_dresses_only_when_asked_and_says_so(tmp_path):
    from swarmpose.cli.main import main

    for name, flag in (("plain", []), ("dressed", ["--clothes"])):
        assert main(["synth", "--motion", "builtin:wave", "--frames", "1", "--out", str(tmp_path / name), "-q",
                     *flag]) == 0
    import cv2

    plain, dressed = (cv2.imread(str(tmp_path / n / "color" / "000000.png")) for n in ("plain", "dressed"))
    depth = [cv2.imread(str(tmp_path / n / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED) for n in ("plain", "dressed")]
    np.testing.assert_array_equal(depth[0], depth[1])  # the depth is the same, and so is the truth
    truths = [(tmp_path / n / "groundtruth.jsonl").read_bytes() for n in ("plain", "dressed")]
    assert truths[0] == truths[1]
    assert np.any(plain != dressed)
    meta = [json.loads((tmp_path / n / "sequence.json").read_text()) for n in ("plain", "dressed")]
    assert [m["clothes"] for m in meta] == [False, True]
