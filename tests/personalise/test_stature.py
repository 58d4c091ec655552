"""The stature measure of the automatic height (:mod:`swarmpose.personalise.stature`): the upright
tests by hand, and the stature against ray-cast (Open3D) subjects of known height alone, on a
floor before a wall (near, and 5.5 m away with the simulator's depth noise), beside a tilted plate,
with a hand over or on the head, and cut off by the image's border."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_NAMES
from swarmpose.core.camera import Intrinsics
from swarmpose.personalise import stature
from swarmpose.personalise.stature import lifted_upright, person_stature, upright

FACING = (0.0, 1.0, 0.0, 0.0)  # upright, facing the camera (OpenCV axes: y down)
K = Intrinsics(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)


def _bent(body, joint: str, angle: float) -> np.ndarray:
    pose = body.rest_pose(translation=(0.0, 0.0, 3.0), quaternion=FACING)
    pose[7 + ANGLE_NAMES.index(joint)] = angle
    return pose


def test_upright_by_hand():
    """The rest pose stands; a knee bent by 0.6 rad or a thigh swung forward by 0.6 rad (both
    beyond the 0.45 rad bound) still stands on the other leg, both legs so bent do not; 0.3 rad
    of either still stands."""
    body = load_body("builtin")
    assert upright(body, body.rest_pose(translation=(0.0, 0.0, 3.0), quaternion=FACING))
    knee, hip = "left_knee.pitch", "right_hip.pitch"  # knee: < 0 flexes; hip: > 0 swings the thigh forward
    assert upright(body, _bent(body, knee, -0.6))  # on the right leg
    assert upright(body, _bent(body, hip, 0.6))  # on the left leg
    both_knees = _bent(body, knee, -0.6)
    both_knees[7 + ANGLE_NAMES.index("right_knee.pitch")] = -0.6
    assert not upright(body, both_knees)
    both_thighs = _bent(body, hip, 0.6)
    both_thighs[7 + ANGLE_NAMES.index("left_hip.pitch")] = 0.6
    assert not upright(body, both_thighs)
    assert upright(body, _bent(body, knee, -0.3))
    assert upright(body, _bent(body, hip, 0.3))


def test_lifted_upright_by_hand():
    """Lifted joints (camera axes, y down) of a person standing, seated facing the camera (thighs
    pointing at it) and squatting; only the standing one is upright; a leg without depth does
    not count; a knee bent beyond ``max_bend_rad`` does not either, where that is asked."""
    up = np.array([0.0, -1.0, 0.0])
    names = ("left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")
    standing = np.array([[0.1, 0.0, 3.0], [0.1, 0.45, 3.0], [0.1, 0.88, 3.05],
                         [-0.1, 0.0, 3.0], [-0.1, 0.45, 2.9], [-0.1, 0.88, 2.95]])
    seated = np.array([[0.1, 0.4, 3.0], [0.1, 0.42, 2.55], [0.1, 0.85, 2.6],
                       [-0.1, 0.4, 3.0], [-0.1, 0.42, 2.55], [-0.1, 0.85, 2.6]])
    squatting = np.array([[0.1, 0.5, 3.0], [0.3, 0.55, 2.6], [0.15, 0.9, 2.9],
                          [-0.1, 0.5, 3.0], [-0.3, 0.55, 2.6], [-0.15, 0.9, 2.9]])
    assert lifted_upright(names, standing, up)
    assert not lifted_upright(names, seated, up)
    assert not lifted_upright(names, squatting, up)
    no_depth = standing.copy()
    no_depth[[1, 4]] = np.nan  # both knees without depth
    assert not lifted_upright(names, no_depth, up)
    # knees forward by 0.2 m over 0.45 m thighs: thighs and shins 24-25 degrees off the vertical (within
    # 34), the knees bent by 49 (beyond the 26 the fitted pose's test allows): upright unless the
    # bend is bounded
    flexed = standing.copy()
    flexed[[1, 4], 2] -= 0.2
    flexed[[2, 5], 2] = flexed[[0, 3], 2]
    assert lifted_upright(names, flexed, up)
    assert not lifted_upright(names, flexed, up, max_bend_rad=stature.UPRIGHT_MAX_RAD)
    assert lifted_upright(names, standing, up, max_bend_rad=stature.UPRIGHT_MAX_RAD)


def _scene_depth(subject, pose: np.ndarray, wall_m: float | None, plate: bool = False,
                 camera: Intrinsics = K) -> np.ndarray:
    """(H, W) m: ``subject`` at ``pose`` ray-cast by Open3D through ``camera``, with a floor under
    its soles and a wall ``wall_m`` behind it (None: the person alone, as on background-free depth;
    0: no hit); ``plate``: a 35 x 60 cm plate tilted by 25 degrees beside the feet instead."""
    import open3d as o3d

    verts = subject.pose(pose[None], "dqs")[0]
    meshes = [(verts, subject.triangles)]
    if plate:
        sole, z = float(verts[:, 1].max()), float(pose[2])
        x = float(verts[verts[:, 1] > sole - 0.1, 0].max()) + 0.02  # just beside the outer foot
        rise = 0.35 * np.tan(0.44)  # 25 degrees: flat enough to look like a floor, too tilted to be one
        corners = [[x, sole, z - 0.3], [x + 0.35, sole - rise, z - 0.3], [x + 0.35, sole - rise, z + 0.3],
                   [x, sole, z + 0.3]]
        meshes.append((np.array(corners), np.array([[0, 1, 2], [0, 2, 3]])))
    if wall_m is not None:
        sole = float(verts[:, 1].max())  # y points down: the lowest point of the body
        back = float(pose[2]) + wall_m
        quad = np.array([[0, 1, 2], [0, 2, 3]])
        meshes += [(np.array([[-5, sole, 0.5], [5, sole, 0.5], [5, sole, 9], [-5, sole, 9]]), quad),
                   (np.array([[-5, -5, back], [5, -5, back], [5, sole, back], [-5, sole, back]]), quad)]
    scene = o3d.t.geometry.RaycastingScene()
    for v, t in meshes:
        scene.add_triangles(o3d.core.Tensor(np.asarray(v, np.float32)), o3d.core.Tensor(np.asarray(t, np.uint32)))
    cols, rows = np.meshgrid(np.arange(camera.width) + 0.0, np.arange(camera.height) + 0.0)
    dirs = np.stack([(cols - camera.cx) / camera.fx, (rows - camera.cy) / camera.fy, np.ones_like(cols)], -1)
    rays = np.concatenate([np.zeros_like(dirs), dirs], -1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # along rays of unit z: the depth
    return np.where(np.isfinite(hit), hit, 0.0).astype(np.float32)


@pytest.mark.slow
@pytest.mark.parametrize("height", [1.50, 1.62, 1.95])
@pytest.mark.parametrize("wall_m", [None, 0.8])
def test_the_stature_is_the_subjects_with_and_without_a_room(height, wall_m):
    """Oracle: a built-in subject of known stature ray-cast (Open3D), alone or standing on a floor
    0.8 m before a wall, seen by the default 1.75 m body at the same pose: the stature is the
    subject's within 2.5 % (the upright share is calibrated on walking subjects, whose heads are
    lower than a straight rest pose's), and on the floor it is measured from the floor's plane."""
    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", f"height={height}")
    pose = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    depth = _scene_depth(subject, pose, wall_m)
    assert person_stature(body, pose, depth, K) == pytest.approx(subject.height, rel=0.025)
    floors = []
    real = stature.floor_plane
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "floor_plane", lambda *a: floors.append(real(*a)) or floors[-1])
        person_stature(body, pose, depth, K)
    if wall_m is None:
        assert floors == [None]
    else:
        (normal, level), = floors
        sole = float(subject.pose(pose[None], "dqs")[0][:, 1].max())  # y down: the floor's y
        assert np.degrees(np.arccos(abs(normal[1]))) < 1.0
        assert level == pytest.approx(-sole, abs=0.005)  # the level along the upward normal


@pytest.mark.parametrize("height", [1.50, 1.62])
def test_without_a_floor_a_leaning_pelvis_does_not_shorten_the_stature(height):
    """A fit whose pelvis leans 15 degrees while its legs and torso stand as the person's (hips
    and spine turned back: the ankles stay within 1 mm, the neck within 6 cm), on background-free
    depth of a ray-cast subject of known stature: the stature is the subject's within 2.5 %. The
    control, measuring along the pelvis's up axis, comes out over 2.5 % short (cos 15 degrees)."""
    from swarmpose.body.kinematics import axis_angle_matrix, matrix_to_quaternion, quaternion_to_matrix

    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", f"height={height}")
    pose = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    depth = _scene_depth(subject, pose, None)
    lean = np.radians(15.0)
    leaning = pose.copy()
    tilt = np.asarray(axis_angle_matrix(np.array([1.0, 0.0, 0.0]), np.array(lean))).reshape(3, 3)
    leaning[3:7] = matrix_to_quaternion(tilt @ quaternion_to_matrix(pose[3:7]))
    for joint, angle in (("left_hip.pitch", lean), ("right_hip.pitch", lean), ("spine.pitch", -lean)):
        leaning[7 + ANGLE_NAMES.index(joint)] = angle
    names = ("neck", "left_ankle", "right_ankle")
    moved = np.linalg.norm(body.posed_points(leaning[None], names)[0] - body.posed_points(pose[None], names)[0], axis=1)
    assert moved[0] < 0.06 and np.all(moved[1:] < 0.001), moved
    assert person_stature(body, leaning, depth, K) == pytest.approx(subject.height, rel=0.025)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "long_axis", lambda marks, up: up)
        assert person_stature(body, leaning, depth, K) < 0.975 * subject.height


@pytest.mark.parametrize("height", [1.62, 1.75])
def test_a_hand_over_the_head_is_not_its_top(height):
    """The left hand raised 25 cm over the head (shoulder roll 2 rad): the stature is still the
    subject's within 2.5 %; the control, without leaving out the points near the fitted forearm,
    measures the hand (over 15 % tall)."""
    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", f"height={height}")
    pose = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    pose[7 + ANGLE_NAMES.index("left_shoulder.roll")] = 2.0
    depth = _scene_depth(subject, pose, 0.8)
    assert person_stature(body, pose, depth, K) == pytest.approx(subject.height, rel=0.025)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "_near_forearms", lambda points, marks: np.zeros(len(points), bool))
        assert person_stature(body, pose, depth, K) > 1.15 * subject.height


def test_no_stature_with_a_hand_on_the_head_or_the_head_or_feet_out_of_the_image():
    body = load_body("builtin").tracking_lod(1500)
    on_head = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    for name, value in (("left_shoulder.roll", -1.0), ("left_shoulder.yaw", -2.5), ("left_elbow.yaw", -1.5)):
        on_head[7 + ANGLE_NAMES.index(name)] = value
    assert person_stature(body, on_head, _scene_depth(body, on_head, 0.8), K) is None  # the wrist 11 cm from it
    for y in (-0.8, 0.9):  # the head above the image's top row, the feet below its bottom row
        pose = body.rest_pose(translation=(0.0, y, 3.2), quaternion=FACING)
        assert person_stature(body, pose, _scene_depth(body, pose, None), K) is None


def test_a_few_flat_pixels_beside_the_feet_are_no_floor():
    """A plate tilted by 25 degrees beside the feet of a subject alone (no floor): its pixels
    must not pass for a floor: the stature stays within 2.5 %; the control, which accepts a plane
    of any size and tilt wherever it lies, is thrown off by more than 3 %."""
    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", "height=1.62")
    pose = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    depth = _scene_depth(subject, pose, None, plate=True)
    assert person_stature(body, pose, depth, K) == pytest.approx(subject.height, rel=0.025)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "FLOOR_PIXELS", 10)
        patch.setattr(stature, "FLAT_PIXELS", 10)
        patch.setattr(stature, "FLOOR_MAX_TILT_RAD", np.pi)
        patch.setattr(stature, "FLOOR_BELOW_FEET_M", (np.inf, np.inf))
        assert abs(person_stature(body, pose, depth, K) / subject.height - 1) > 0.03


@pytest.mark.parametrize("height", [1.50, 1.95])
def test_at_range_the_floor_is_found_among_noisy_pixels(height):
    """Oracle: a built-in subject 5.5 m away on a floor 0.8 m before a wall, ray-cast (Open3D) at
    640 x 480 with the simulator's Kinect noise (three seeds): there the noise turns the floor's
    normals every way, and the floor is fitted among all the low pixels around the feet. The
    median stature is the subject's within 1 %; the control, which looks for the floor among
    flat pixels only and so takes the soles among noisy floor points, is more than 1.5 % tall."""
    from dataclasses import replace

    from swarmpose.sim.depth_noise import KinectNoise

    camera = replace(K, width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", f"height={height}")
    pose = body.rest_pose(translation=(0.0, 0.1, 5.5), quaternion=FACING)
    clean = _scene_depth(subject, pose, 0.8, camera=camera)
    noisy = [KinectNoise().apply(clean, np.random.default_rng(seed)) for seed in range(3)]
    measured = np.median([person_stature(body, pose, depth, camera) for depth in noisy])
    assert measured == pytest.approx(subject.height, rel=0.01)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "FLAT_PIXELS", 0)
        control = np.median([person_stature(body, pose, depth, camera) for depth in noisy])
    assert control > 1.015 * subject.height


def test_without_a_floor_a_fit_whose_feet_miss_the_persons_finds_none():
    """A 1.50 m built-in subject alone (no floor, as on background-free depth) at 2.5 m, 640 x 480,
    seen by the 1.75 m body at the same root: the model's feet lie below the person's, whose shoes
    and shins are left outside the render, few of them flat. No floor is found among them and the
    stature is the subject's within 2.5 %; the control, which lets that fallback plane tilt as far
    as a flat floor may (20 degrees), takes the shoes for a floor and measures over 5 % short."""
    from dataclasses import replace

    camera = replace(K, width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
    body = load_body("builtin").tracking_lod(1500)
    subject = load_body("builtin", "height=1.50")
    pose = body.rest_pose(translation=(0.0, 0.1, 2.5), quaternion=FACING)
    depth = _scene_depth(subject, pose, None, camera=camera)
    floors = []
    real = stature.floor_plane
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "floor_plane", lambda *a: floors.append(real(*a)) or floors[-1])
        assert person_stature(body, pose, depth, camera) == pytest.approx(subject.height, rel=0.025)
    assert floors == [None]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stature, "FALLBACK_MAX_TILT_RAD", stature.FLOOR_MAX_TILT_RAD)
        assert person_stature(body, pose, depth, camera) < 0.95 * subject.height


def test_no_stature_without_a_person_in_the_depth():
    body = load_body("builtin").tracking_lod(1500)
    pose = body.rest_pose(translation=(0.0, 0.1, 3.2), quaternion=FACING)
    assert person_stature(body, pose, np.zeros((K.height, K.width), np.float32), K) is None
    far_away = body.rest_pose(translation=(0.0, 0.1, 300.0), quaternion=FACING)  # a few pixels at most
    assert person_stature(body, far_away, np.full((K.height, K.width), 3.0, np.float32), K) is None
