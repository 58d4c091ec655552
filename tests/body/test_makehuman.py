"""The MakeHuman body: presets, rig, weights, named points and the tracking level of detail."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import MAKEHUMAN, needs_assets, surface_distance

from swarmpose.core.errors import AssetError, ConfigError

pytestmark = needs_assets

REQUIRED_PRESETS = ("male", "female", "male-heavy", "female-slim", "male-tall", "female-short")


@pytest.fixture(scope="module")
def load():
    from swarmpose.body.makehuman import load_makehuman
    return lambda preset: load_makehuman(str(MAKEHUMAN), preset)


def _volume(body) -> float:
    return trimesh.Trimesh(body.vertices, body.triangles, process=False).volume


def test_every_required_preset_has_a_plausible_height(load):
    heights = {p: load(p).height for p in REQUIRED_PRESETS}
    assert all(1.55 <= h <= 1.95 for h in heights.values()), heights
    assert heights["male-tall"] > heights["male"] + 0.1
    assert heights["female-short"] < heights["female"] - 0.03
    assert heights["male"] > heights["female"]


def test_weight_targets_change_girth_not_height(load):
    male, heavy = load("male"), load("male-heavy")
    female, slim = load("female"), load("female-slim")
    assert _volume(heavy) > 1.07 * _volume(male)
    assert _volume(slim) < 0.95 * _volume(female)
    assert abs(heavy.height - male.height) < 0.01
    # A plausible human volume (density ~1 kg/L): 45..130 litres.
    assert all(0.035 < _volume(load(p)) < 0.13 for p in REQUIRED_PRESETS)


def test_mesh_is_the_body_group_in_metres(load):
    body = load("male")
    assert body.vertices.shape == (13380, 3) and body.triangles.shape == (26756, 3)
    assert len(body.bone_names) == 31 and body.bone_names[0] == "Hips"
    np.testing.assert_allclose(body.bone_heads[0], 0.0, atol=1e-12)


def test_skin_weights_are_sparse_normalised_and_anatomical(load):
    body = load("male")
    assert body.skin_indices.shape[1] == 4
    np.testing.assert_allclose(body.skin_weights.sum(axis=1), 1.0, atol=1e-5)
    dominant = body.skin_indices[np.arange(len(body.vertices)), np.argmax(body.skin_weights, axis=1)]
    names = np.array(body.bone_names)[dominant]
    # The lowest vertices belong to the feet/toes, the highest to the head.
    assert set(names[np.argsort(body.vertices[:, 1])[:50]]) <= {"LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"}
    assert set(names[np.argsort(body.vertices[:, 1])[-50:]]) == {"Head"}


def test_named_points_sit_where_anatomy_says(load):
    body = load("female")
    p = body.point
    assert p("head")[1] > p("neck")[1] > p("left_shoulder")[1] - 0.1 > p("left_hip")[1]
    assert p("left_hip")[1] > p("left_knee")[1] > p("left_ankle")[1] > p("left_toe")[1] - 0.05
    assert p("left_shoulder")[0] > 0 > p("right_shoulder")[0]
    assert p("nose")[2] > p("head")[2] + 0.05
    assert p("left_ear")[0] > p("left_eye")[0] > 0
    assert p("left_toe")[2] > p("left_ankle")[2] > p("left_heel")[2]
    joints = ["left_shoulder", "left_elbow", "left_wrist", "left_hip", "left_knee", "left_ankle", "neck", "head"]
    dist = surface_distance(body.vertices, body.triangles, np.stack([p(j) for j in joints]))
    assert np.all(dist < 0.1), dict(zip(joints, dist))


def test_joint_axes_mean_the_anatomical_motion(load):
    """Each angle moved from 0 (the T-pose value) moves the limb the way Table 1 means."""
    from swarmpose.body.skeleton import ANGLE_NAMES

    body = load("male")
    rest = body.rest_pose()  # camera frame = body frame: X left, Y up, Z forward

    def moved(angle: str, value: float, point: str) -> np.ndarray:
        k = 7 + ANGLE_NAMES.index(angle)
        at_zero, at_value = rest.copy(), rest.copy()
        at_zero[k], at_value[k] = 0.0, value
        pts = body.posed_points(np.stack([at_zero, at_value]), [point])[:, 0]
        return pts[1] - pts[0]

    assert moved("left_hip.pitch", 1.0, "left_knee")[2] > 0.2  # hip flexion: thigh forward
    assert moved("right_hip.pitch", 1.0, "right_knee")[2] > 0.2
    assert moved("left_knee.pitch", -1.5, "left_ankle")[2] < -0.2  # knee flexion: shin backward
    assert moved("left_elbow.yaw", -1.5, "left_wrist")[2] > 0.15  # elbow flexion: forearm forward
    assert moved("right_elbow.yaw", 1.5, "right_wrist")[2] > 0.15
    assert moved("spine.pitch", 0.5, "neck")[2] > 0.1  # spine flexion: bend forward
    assert moved("neck.pitch", 0.3, "nose")[1] < -0.005  # nod forward: the nose goes down
    assert moved("left_shoulder.roll", 1.0, "left_elbow")[1] > 0.1  # raises the arm
    assert moved("right_shoulder.roll", -1.0, "right_elbow")[1] > 0.1
    assert moved("left_shoulder.yaw", -1.0, "left_elbow")[2] > 0.1  # left shoulder yaw < 0: forward
    assert moved("right_shoulder.yaw", 1.0, "right_elbow")[2] > 0.1
    assert moved("left_ankle.pitch", 0.5, "left_toe")[1] < -0.03  # pitch > 0 points the toes down
    assert moved("spine.roll", 0.4, "neck")[0] < -0.05  # roll about +Z bends towards the subject's right


def test_rest_angles_describe_an_a_pose(load):
    from swarmpose.body.skeleton import ANGLE_NAMES
    rest = dict(zip(ANGLE_NAMES, load("male").rest_angles))
    assert -1.2 < rest["left_shoulder.roll"] < -0.4 and 0.4 < rest["right_shoulder.roll"] < 1.2  # arms down
    assert rest["left_elbow.yaw"] < -0.3 and rest["right_elbow.yaw"] > 0.3  # elbows slightly bent


def test_rest_pose_reproduces_rest_mesh_with_both_skinnings(load):
    body = load("male")
    h = body.rest_pose()[None]
    for method in ("lbs", "dqs"):
        np.testing.assert_allclose(body.pose(h, method)[0], body.vertices, atol=1e-9)


def test_tracking_lod_keeps_skinning_and_surface(load):
    from swarmpose.body.skeleton import ANGLE_LIMITS, neutral_pose
    body = load("male")
    lod = body.tracking_lod(1500)
    assert 1300 <= len(lod.triangles) <= 1700
    np.testing.assert_allclose(lod.skin_weights.sum(axis=1), 1.0, atol=1e-5)
    rng = np.random.default_rng(5)
    h = np.tile(neutral_pose(), (3, 1))
    h[:, 7:] = rng.uniform(ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1]) * 0.4
    full = body.pose(h)
    low = lod.pose(h)
    for i in range(3):  # every decimated vertex stays near the full-resolution posed surface
        dist = surface_distance(full[i], body.triangles, low[i])
        assert np.median(dist) < 0.01 and np.max(dist) < 0.06


@pytest.mark.parametrize("preset", ["male", "female-short"])
def test_a_body_and_its_glb_give_the_same_tracking_mesh(load, preset, tmp_path):
    """The decimation is not continuous in its input: the float32 positions glTF stores (at most
    3e-8 m off) give another tracking mesh (before the exact positions travelled: 0.8 mm apart on
    average, 41 mm at most, and 25.3 against 24.7 mm on a female walk). The GLB keeps the exact ones."""
    from dataclasses import replace

    from swarmpose.body.gltf_read import load_glb
    from swarmpose.body.gltf_write import save_glb
    body = load(preset)
    back = load_glb(save_glb(body, tmp_path / "body.glb"))
    np.testing.assert_array_equal(back.vertices, body.vertices)
    mine, theirs = body.tracking_lod(1500), back.tracking_lod(1500)
    np.testing.assert_array_equal(theirs.triangles, mine.triangles)
    np.testing.assert_array_equal(theirs.vertices, mine.vertices)
    np.testing.assert_array_equal(theirs.skin_indices, mine.skin_indices)
    np.testing.assert_array_equal(theirs.skin_weights, mine.skin_weights)
    rounded = replace(body, vertices=body.vertices.astype(np.float32).astype(np.float64)).tracking_lod(1500)
    assert len(rounded.vertices) != len(mine.vertices) or np.abs(rounded.vertices - mine.vertices).max() > 1e-3


def test_bad_inputs_name_the_problem(tmp_path):
    from swarmpose.body.makehuman import load_makehuman
    with pytest.raises(ConfigError, match="unknown MakeHuman shape preset 'giant'.*male"):
        load_makehuman(str(MAKEHUMAN), "giant")
    with pytest.raises(AssetError, match="no base.obj"):
        load_makehuman(str(tmp_path), "male")


def test_a_body_from_the_cache_is_the_body_parsed_from_the_files(tmp_path, monkeypatch):
    """base.obj's parse and the skin from the 3 MB weights file are cached (a start's 0.5-1 s): a load
    from the cache gives the same arrays as a load that parses the files, and an edited file is
    parsed again."""
    import shutil

    from swarmpose.body import makehuman

    def fresh_load(directory):
        makehuman._read_obj.cache_clear()
        makehuman._rig_assets.cache_clear()
        makehuman.load_makehuman.cache_clear()
        return makehuman.load_makehuman(str(directory), "female")

    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path / "cache"))
    parsed = fresh_load(MAKEHUMAN)
    assert (tmp_path / "cache" / "makehuman_obj").is_dir() and (tmp_path / "cache" / "makehuman_skin").is_dir()
    cached = fresh_load(MAKEHUMAN)
    for name in ("vertices", "triangles", "skin_indices", "skin_weights", "bone_heads", "point_rest"):
        np.testing.assert_array_equal(getattr(cached, name), getattr(parsed, name), err_msg=name)
    copy = tmp_path / "makehuman"
    shutil.copytree(MAKEHUMAN, copy)
    obj = copy / "base.obj"
    obj.chmod(0o644)
    obj.write_text(obj.read_text().replace("\nv ", "\nv 0.5 0 0 #\nv ", 1))  # a vertex first: the others shift
    moved = fresh_load(copy)
    assert not np.array_equal(moved.vertices, parsed.vertices)
    makehuman.load_makehuman.cache_clear()
