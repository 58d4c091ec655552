"""The floor-aligned world frame (``--floor``, ``--coordinates world``).

Oracles: hand geometry (a level camera's world frame is the camera turned 180 degrees about x;
a camera pitched and rolled by known angles at a known height over an analytically rendered
floor), ``look_at`` of the renderer for the pitch, forward kinematics for moved poses, and on
a synthetic sequence the renderer's own camera placement (``sequence.json``: the true floor and
world frame), the skinned mesh (the soles on the floor) and the BVH read back with the repo's
reader.
"""

from __future__ import annotations

import json
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from swarmpose.body.kinematics import forward_kinematics
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_LIMITS, EVAL_JOINTS
from swarmpose.cli.main import main
from swarmpose.core.camera import Intrinsics, look_at
from swarmpose.core.errors import ConfigError
from swarmpose.core.world import (
    camera_angles,
    load_extrinsics,
    normal_of_angles,
    transform_points,
    transform_poses,
    world_from_floor,
)
from swarmpose.detect.floor import fit_floor
from swarmpose.messages import info_message, validate
from swarmpose.motion.bvh import read_bvh
from swarmpose.pipeline.config import ServiceConfig
from swarmpose.pipeline.run import results
from swarmpose.pipeline.service import open_parts
from swarmpose.pipeline.world import WorldFrame, make_world
from swarmpose.sources.base import Frame
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult, lost_body

FAST = TrackerConfig(particles=16, generations=12)


def plane_depth(normal: np.ndarray, height: float, intr: Intrinsics, max_depth: float = 8.0) -> np.ndarray:
    """Depth (H, W) m of the floor ``normal @ p + height = 0`` seen by pinhole ``intr`` (0 where
    a ray misses it or it lies beyond ``max_depth``): ray-plane intersection per pixel."""
    u, v = np.meshgrid(np.arange(intr.width, dtype=np.float64), np.arange(intr.height, dtype=np.float64))
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1)
    with np.errstate(divide="ignore"):
        z = -height / (rays @ normal)
    return np.where((z > 0) & (z < max_depth), z, 0.0).astype(np.float32)


def rotation_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------------- geometry
def test_a_level_camera_world_is_the_camera_turned_upright_with_its_origin_under_the_point():
    point = np.array([0.3, 0.2, 3.0])  # camera frame: 0.2 m below the lens, 3 m ahead
    t = world_from_floor(np.array([0.0, -1.0, 0.0]), 1.5, point)
    np.testing.assert_allclose(t[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    # by hand: the floor point under ``point`` is (0.3, 1.5, 3.0) in the camera frame (y down)
    np.testing.assert_allclose(transform_points(t, [0.3, 1.5, 3.0]), [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(transform_points(t, point), [0, 1.3, 0], atol=1e-12)  # 1.3 m above the floor
    np.testing.assert_allclose(transform_points(t, [0, 0, 0]), [-0.3, 1.5, 3.0], atol=1e-12)  # the lens
    np.testing.assert_allclose(transform_points(t, [1.3, 0.2, 3.0]), [1.0, 1.3, 0.0], atol=1e-12)  # x stays x


def test_pitch_and_roll_angles_match_the_renderers_look_at_and_invert():
    eye = np.array([0.0, 1.4, 0.0])
    for pitch in (0.0, 12.0, 35.0):  # look down by ``pitch``: the renderer's world -> camera rotation
        target = eye + [0.0, -np.tan(np.radians(pitch)), -1.0]
        up_in_camera = look_at(eye, target) @ [0.0, 1.0, 0.0]
        np.testing.assert_allclose(normal_of_angles(pitch), up_in_camera, atol=1e-12)
        for roll in (-20.0, 0.0, 7.5):
            got = camera_angles(normal_of_angles(pitch, roll))
            assert got == pytest.approx((pitch, roll), abs=1e-9)
    # a roll turns the up direction about the optical axis, towards the image's right (+x)
    np.testing.assert_allclose(normal_of_angles(0.0, 30.0), rotation_z(30.0) @ [0.0, -1.0, 0.0], atol=1e-12)
    assert normal_of_angles(0.0, 30.0)[0] > 0


@pytest.mark.parametrize(("pitch", "roll", "height"), [(20.0, 0.0, 1.4), (8.0, 6.0, 0.9), (40.0, -4.0, 2.5)])
def test_a_fitted_floor_of_a_pitched_camera_gives_its_height_and_a_world_on_the_floor(pitch, roll, height):
    intr = Intrinsics.kinect_v1()
    normal = normal_of_angles(pitch, roll)
    depth = plane_depth(normal, height, intr)
    plane = fit_floor(depth, intr)
    assert plane is not None
    assert np.degrees(np.arccos(np.clip(plane.normal @ normal, -1, 1))) < 0.2
    assert plane.offset == pytest.approx(height, abs=0.005)

    ahead = np.array([0.4, 0.0, 3.0])  # a point 3 m ahead of the lens: the origin goes under it
    t = world_from_floor(plane.normal, plane.offset, ahead)
    r = t[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0)
    v, u = np.nonzero(depth[::16, ::16])
    z = depth[::16, ::16][v, u]
    floor_points = np.stack([(16 * u - intr.cx) / intr.fx * z, (16 * v - intr.cy) / intr.fy * z, z], -1)
    assert np.abs(transform_points(t, floor_points)[:, 1]).max() < 0.01  # the floor is y = 0
    lens = transform_points(t, [0.0, 0.0, 0.0])
    assert lens[1] == pytest.approx(height, abs=0.005)  # the lens stands ``height`` above it
    under = transform_points(t, ahead)
    assert under[[0, 2]] == pytest.approx([0.0, 0.0], abs=1e-9)  # the origin lies straight below the point
    # x: the camera's x on the floor (no height), z points back at the camera (right-handed)
    right = transform_points(t, [1.0, 0.0, 0.0]) - lens  # (rolled: it rises or falls, but never turns in z)
    assert right[2] == pytest.approx(0.0, abs=1e-9) and right[0] > 0.9
    assert (transform_points(t, ahead) - lens)[2] < 0  # the scene lies towards -z


def test_moved_poses_give_the_moved_joints():
    body = load_body("builtin")
    rng = np.random.default_rng(5)
    poses = np.zeros((6, 36))
    poses[:, 0:3] = rng.uniform(-1, 1, (6, 3)) + [0, 0, 3]
    poses[:, 3:7] = rng.normal(size=(6, 4))
    poses[:, 3:7] /= np.linalg.norm(poses[:, 3:7], axis=1, keepdims=True)
    poses[:, 7:] = rng.uniform(ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1], (6, 29))
    t = world_from_floor(normal_of_angles(17.0, 3.0), 1.3, [0.2, 0.1, 2.5])
    _, heads = forward_kinematics(body.rig, poses)
    _, moved = forward_kinematics(body.rig, transform_poses(t, poses))
    np.testing.assert_allclose(moved, transform_points(t, heads), atol=1e-9)
    np.testing.assert_allclose(transform_poses(t, poses)[:, 7:], poses[:, 7:])  # joint angles stay


# ---------------------------------------------------------------------------- extrinsics
def write(path: Path, data) -> Path:
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_the_three_extrinsics_forms_give_the_same_floor(tmp_path):
    pitch, height = 14.0, 1.25
    normal = normal_of_angles(pitch, 2.0)
    full = world_from_floor(normal, height, [0.1, 0.3, 2.0])
    by_matrix = load_extrinsics(write(tmp_path / "m.json", {"camera_to_world": full.tolist()}))
    by_floor = load_extrinsics(write(tmp_path / "f.json", {"floor": {"normal": (3 * normal).tolist(),
                                                                      "offset_m": 3 * height}}))
    by_angles = load_extrinsics(write(tmp_path / "a.json", {"camera_height_m": height, "pitch_deg": pitch,
                                                            "roll_deg": 2.0}))
    for state in (by_matrix, by_floor, by_angles):
        np.testing.assert_allclose(state.floor_normal, normal, atol=1e-9)
        assert state.floor_offset_m == pytest.approx(height) and state.source == "extrinsics"
    np.testing.assert_allclose(by_matrix.camera_to_world, full, atol=1e-12)  # used as it is
    assert by_floor.camera_to_world is None and by_angles.camera_to_world is None  # the origin comes later


@pytest.mark.parametrize(("content", "match"), [
    (None, "not found"),
    ("{not json", "is not JSON"),
    ([1, 2], "must be a JSON object"),
    ({"rotation": 1}, "no extrinsics found"),
    ({"camera_to_world": [[1, 0, 0], [0, 1, 0]]}, "4 rows of 4"),
    ({"camera_to_world": (2 * np.eye(4)).tolist()}, "last row of camera_to_world must be"),
    ({"camera_to_world": np.diag([2.0, 2.0, 2.0, 1.0]).tolist()}, "not a rotation"),
    ({"camera_to_world": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}, "not a rotation"),
    ({"camera_to_world": np.eye(4).tolist()}, "0 m above the floor"),
    ({"floor": {"normal": [0, 0, 0], "offset_m": 1}}, "normal is zero"),
    ({"floor": {"normal": [0, -1, 0], "offset_m": -1.2}}, "negate both"),
    ({"floor": {"normal": [0, -1], "offset_m": 1.2}}, "list of 3 numbers"),
    ({"floor": {"normal": [0, -1, 0]}}, "normal and offset_m"),
    ({"camera_height_m": "tall"}, "camera_height_m must be a finite number"),
    ({"camera_height_m": 1.2, "pitch_deg": 95}, "within -90..90"),
])
def test_bad_extrinsics_files_are_refused_naming_the_file(tmp_path, content, match):
    path = tmp_path / "extrinsics.json"
    if content is not None:
        write(path, content)
    with pytest.raises(ConfigError, match=match) as info:
        load_extrinsics(path)
    assert str(path) in str(info.value)


def test_world_coordinates_need_a_floor():
    assert make_world("off", "camera") is None
    with pytest.raises(ConfigError, match="--coordinates world needs a floor"):
        make_world("off", "world")
    with pytest.raises(ConfigError, match="--floor is empty"):
        make_world(" ", "camera")


def test_the_cli_refuses_a_world_without_floor_and_a_missing_extrinsics_file(wave_sequence, tmp_path, capsys):
    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "a"), "--coordinates", "world",
                 "--floor", "off", "--quiet"]) == 2
    assert "--coordinates world needs a floor" in capsys.readouterr().err
    missing = tmp_path / "nowhere.json"
    assert main(["track", str(wave_sequence), "--out", str(tmp_path / "b"), "--floor", str(missing), "--quiet"]) == 2
    assert f"extrinsics file {missing} not found" in capsys.readouterr().err


# ---------------------------------------------------------------------------- the state machine
def a_body(root: tuple[float, float, float], state: str = "tracking") -> BodyResult:
    pose = np.zeros(36)
    pose[0:3], pose[3] = root, 1.0
    n = len(EVAL_JOINTS)
    return BodyResult(0, state, "", pose, np.zeros((n, 3)), np.zeros((n, 2)), np.ones(n))


def test_the_world_frame_waits_for_the_floor_then_the_first_tracked_body_and_stays():
    intr = Intrinsics(160, 120, 130.0, 130.0, 79.5, 59.5)
    normal, height = normal_of_angles(15.0), 1.1
    floor = plane_depth(normal, height, intr)
    world = WorldFrame("auto", "world")
    blank = Frame(0, 0, np.zeros_like(floor), None, intr)
    world.observe_depth(blank)
    assert world.observe_bodies([a_body((0, 0, 3))]) is None and world.info()["floor"] is None  # no floor yet
    world.observe_depth(Frame(1, 0, floor, None, intr))
    state = world.observe_bodies([lost_body("nobody")])  # the floor, but nobody to stand on it yet
    assert state.camera_to_world is None and state.source == "depth"
    assert state.floor_offset_m == pytest.approx(height, abs=0.01)
    root = np.array([0.2, 0.1, 2.8])
    state = world.observe_bodies([a_body(tuple(root), "init")])
    assert transform_points(state.camera_to_world, root)[[0, 2]] == pytest.approx([0, 0], abs=1e-9)
    later = world.observe_bodies([a_body((1.0, 0.0, 4.0))])  # the origin stays where the person started
    np.testing.assert_array_equal(later.camera_to_world, state.camera_to_world)
    info = world.info()
    assert info["coordinates"] == "world" and info["floor"]["pitch_deg"] == pytest.approx(15.0, abs=0.3)
    validate(info_message("cam0", world=info))
    world.observe_depth(Frame(2, 0, np.zeros((60, 80), np.float32), None, Intrinsics(80, 60, 65, 65, 39.5, 29.5)))
    assert world.state is None  # another camera: its floor is fitted again


# ---------------------------------------------------------------------------- end to end
def true_camera_to_world(sequence: Path) -> np.ndarray:
    """The renderer's camera -> world transform of a synth sequence (its world: y up, floor y = 0)."""
    camera = json.loads((sequence / "sequence.json").read_text())["camera"]
    out = np.eye(4)
    out[:3, :3] = np.asarray(camera["world_to_camera_rotation"]).T
    out[:3, 3] = camera["eye_world_m"]
    return out


def run(sequence: Path, out: Path, **settings):
    """Track ``sequence`` into ``out`` (files) with ``settings``; (parts, [(result, message)])."""
    config = ServiceConfig(source=f"folder:{sequence}", overlay=False, tracker=FAST, **settings)
    got = []
    with ExitStack() as stack:
        parts = open_parts(config, stack, out=str(out))
        for result in results(parts.source, parts.pipeline):
            message = validate(result.to_message("cam0"))
            for sink in parts.sinks:
                sink.frame(message, None)
            got.append((result, message))
        for sink in parts.sinks:
            sink.close()
    return parts, got


@pytest.fixture(scope="module")
def world_run(wave_sequence, tmp_path_factory):
    return run(wave_sequence, tmp_path_factory.mktemp("world"), coordinates="world")


@pytest.mark.slow
def test_world_joints_are_the_camera_joints_moved_onto_the_fitted_floor(world_run, wave_sequence):
    parts, got = world_run
    state = parts.pipeline.world.state
    n, d = state.floor_normal, state.floor_offset_m
    # the floor the renderer put there (sequence.json) within a degree and 3 cm
    truth = true_camera_to_world(wave_sequence)
    true_up = truth[1, :3]
    assert np.degrees(np.arccos(np.clip(n @ true_up, -1, 1))) < 1.0
    assert d == pytest.approx(truth[1, 3], abs=0.03)
    # numpy oracle: axes from the plane by hand, origin under the first frame's root
    root = got[0][0].bodies[0].pose[0:3]
    x = np.array([1.0, 0.0, 0.0]) - n[0] * n
    x /= np.linalg.norm(x)
    axes = np.stack([x, n, np.cross(x, n)])
    origin = root - (n @ root + d) * n
    for result, message in got:
        assert message["coordinates"] == "world"
        np.testing.assert_allclose(message["camera_to_world"], got[0][1]["camera_to_world"])  # fixed
        camera = replace(result, coordinates="camera").to_message("cam0")
        assert camera["coordinates"] == "camera" and camera["camera_to_world"] == message["camera_to_world"]
        for name in EVAL_JOINTS:
            p_cam = np.asarray(camera["bodies"][0]["joints"][name]["position_m"])
            p_world = message["bodies"][0]["joints"][name]["position_m"]
            np.testing.assert_allclose(p_world, axes @ (p_cam - origin), atol=2e-6)
        head = message["bodies"][0]["joints"]["head"]
        assert head["pixel"] == camera["bodies"][0]["joints"]["head"]["pixel"]  # pixels stay pixels
    first = np.asarray(got[0][1]["bodies"][0]["pose"][0:3])
    assert first[[0, 2]] == pytest.approx([0.0, 0.0], abs=1e-5)  # the origin lies under the start


def test_the_true_skeleton_and_the_tracked_soles_stand_on_the_world_floor(world_run, wave_sequence):
    parts, got = world_run
    t = np.asarray(got[0][1]["camera_to_world"])
    truth = parts.source.ground_truth
    heights = transform_points(t, truth.joints3d)[..., 1]
    true_heights = transform_points(true_camera_to_world(wave_sequence), truth.joints3d)[..., 1]
    np.testing.assert_allclose(heights, true_heights, atol=0.03)  # heights as the renderer made them
    soles = parts.body.pose(transform_poses(t, truth.poses))[..., 1].min(axis=1)
    assert np.abs(soles).max() < 0.03  # the true body's soles on the fitted floor (the renderer put them at 0)
    ankles = [j for j, name in enumerate(EVAL_JOINTS) if name.endswith("ankle")]
    tracked = np.array([[m["bodies"][0]["joints"][EVAL_JOINTS[j]]["position_m"][1] for j in ankles] for _, m in got])
    # the lowest tracked ankle stands as high over the floor as the true one (tracking error included)
    np.testing.assert_allclose(tracked.min(axis=1), true_heights[:, ankles].min(axis=1), atol=0.03)


def test_eval_scores_world_coordinates_as_camera_ones(world_run):
    parts, got = world_run
    truth = parts.source.ground_truth
    errors = []
    for result, _ in got:  # Δ by hand from the camera-frame joints
        joints = result.bodies[0].joints3d
        errors.append(np.linalg.norm(joints - truth.joints3d[truth.row(result.index)], axis=1))
    assert parts.score.summary()["mpjpe_mm"] == pytest.approx(1000 * np.mean(errors), abs=0.01)


def test_the_bvh_stands_upright_on_the_floor_at_the_pelvis_height(world_run):
    parts, got = world_run
    out = Path(parts.outputs[0]).parent
    clip = read_bvh(out / "poses.bvh")
    assert len(clip) == len(got)
    rot, pos = clip.global_transforms()
    roots = np.array([m["bodies"][0]["pose"][0:3] for _, m in got])
    np.testing.assert_allclose(clip.root_positions / 100.0, roots, atol=1e-5)  # the world root, cm
    pelvis = parts.body.floor_offset  # the root's height over the soles standing
    assert np.abs(clip.root_positions[:, 1] / 100.0 - pelvis).max() < 0.08
    neck = pos[:, clip.joint_index("neck")] - pos[:, 0]
    up = neck[:, 1] / np.linalg.norm(neck, axis=1)
    assert np.degrees(np.arccos(up)).max() < 20  # upright: pelvis -> neck within 20 degrees of +Y
    head_y = pos[:, clip.joint_index("head"), 1]
    assert np.all(head_y > 150)  # cm above the floor


@pytest.mark.slow
def test_given_extrinsics_put_the_joints_in_the_renderers_world(wave_sequence, tmp_path):
    truth_t = true_camera_to_world(wave_sequence)
    extrinsics = write(tmp_path / "camera.json", {"camera_to_world": truth_t.tolist()})
    parts, got = run(wave_sequence, tmp_path / "out", coordinates="world", floor=str(extrinsics))
    truth = parts.source.ground_truth
    assert parts.pipeline.world.info()["floor"]["source"] == "extrinsics"
    for result, message in got:
        np.testing.assert_allclose(message["camera_to_world"], truth_t, atol=1e-6)
        world = np.array([message["bodies"][0]["joints"][j]["position_m"] for j in EVAL_JOINTS])
        true_world = transform_points(truth_t, truth.joints3d[truth.row(result.index)])
        assert np.median(np.linalg.norm(world - true_world, axis=1)) < 0.1  # tracking error, not a frame error
    clip = read_bvh(tmp_path / "out" / "poses.bvh")
    np.testing.assert_allclose(clip.root_positions[0] / 100.0, got[0][1]["bodies"][0]["pose"][0:3], atol=1e-5)
