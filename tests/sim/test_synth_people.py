"""`swarmpose synth` with several people: per-person ground truth against independent oracles.

The scene: a man walking in front (person 1), a woman walking behind him and to his right
so that he hides part of her (person 2), and a short woman waving beside them, turned 30
degrees (person 3). Oracles: the pinhole projection by hand, numpy forward kinematics of
each recorded pose, and Open3D ray casts of the people's meshes (alone and together) cast
through pixel centres computed by hand.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP, needs_assets, synthesize_scene

from swarmpose.body.kinematics import axis_angle_matrix, quaternion_to_matrix
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import COCO17, EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import AssetError, ConfigError
from swarmpose.detect.simulated import SimulatedDetector
from swarmpose.motion.builtin import builtin_motion
from swarmpose.sim.scene import load_people, load_scene_file, parse_person_spec
from swarmpose.sim.synth import SynthConfig, occluded_points, synthesize, synthesize_people
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import load_ground_truth

INTR = Intrinsics.kinect_v1()
FRAMES = 4
PEOPLE = ("builtin:male:builtin:walk@0.05,0.6", "builtin:female:builtin:walk@-0.6,-0.9",
          "builtin:female-short:builtin:wave@1.0,-0.4,30")
SHAPES = ("male", "female", "female-short")
FRONT, BEHIND = 0, 1
MARGIN = 0.05


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    return synthesize_scene(tmp_path_factory.mktemp("people"), PEOPLE, FRAMES, seed=2)


@cache
def _body(shape: str):
    return load_body("builtin", shape)


def _records(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "groundtruth.jsonl").read_text().splitlines()]


def _mesh(k: int, person: dict) -> tuple[np.ndarray, np.ndarray]:
    body = _body(SHAPES[k])
    return body.pose(np.asarray(person["pose"])[None], "dqs")[0], body.triangles


def _cast(meshes, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth (N,) and the index of the mesh hit (N,; -1 none) along the rays through pixel
    centres (N, 2) (OpenCV: pixel (u, v) is centred at u, v), by Open3D's RaycastingScene."""
    import open3d as o3d

    rc = o3d.t.geometry.RaycastingScene()
    ids = [rc.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
           for v, f in meshes]
    d = np.stack([(pixels[:, 0] - INTR.cx) / INTR.fx, (pixels[:, 1] - INTR.cy) / INTR.fy, np.ones(len(pixels))], 1)
    rays = np.concatenate([np.zeros_like(d), d], axis=1).astype(np.float32)
    hit = rc.cast_rays(o3d.core.Tensor(rays))
    t = hit["t_hit"].numpy()
    geom = hit["geometry_ids"].numpy().astype(np.int64)
    who = np.full(len(pixels), -1)
    for k, gid in enumerate(ids):
        who[np.isfinite(t) & (geom == gid)] = k
    return t, who  # the ray's z component is 1, so t is the depth z


def _all_pixels() -> np.ndarray:
    v, u = np.mgrid[0:INTR.height, 0:INTR.width]
    return np.stack([u.ravel(), v.ravel()], 1).astype(np.float64)


def test_each_persons_joints2d_are_the_projection_of_its_joints3d(scene):
    for r in _records(scene):
        assert [p["id"] for p in r["people"]] == [1, 2, 3]
        for p in r["people"]:
            for name in EVAL_JOINTS:
                x, y, z = p["joints3d"][name]
                assert p["joints2d"][name] == pytest.approx([525 * x / z + 319.5, 525 * y / z + 239.5], abs=2e-3)


def test_each_persons_joints3d_are_its_bodys_fk_of_its_pose(scene):
    for r in _records(scene):
        for k, p in enumerate(r["people"]):
            fk = _body(SHAPES[k]).posed_points(np.asarray(p["pose"])[None], EVAL_JOINTS)[0]
            np.testing.assert_allclose([p["joints3d"][j] for j in EVAL_JOINTS], fk, atol=2e-6)
        # Person 1's fields stay at the top of the record, for single-person readers.
        assert {key: r[key] for key in ("pose", "joints3d", "joints2d", "detections")} == \
            {key: r["people"][0][key] for key in ("pose", "joints3d", "joints2d", "detections")}


def test_people_start_where_asked_stand_on_the_floor_and_face_their_yaw(scene):
    meta = json.loads((scene / "sequence.json").read_text())
    rot, eye = np.array(meta["camera"]["world_to_camera_rotation"]), np.array(meta["camera"]["eye_world_m"])
    assert [(p["id"], p["x"], p["z"], p["yaw"]) for p in meta["people"]] == \
        [(1, 0.05, 0.6, 0.0), (2, -0.6, -0.9, 0.0), (3, 1.0, -0.4, 30.0)]
    records = _records(scene)
    for k, spec in enumerate(meta["people"]):
        root = rot.T @ np.array(records[0]["people"][k]["pose"][:3]) + eye
        assert root[[0, 2]] == pytest.approx([spec["x"], spec["z"]], abs=1e-9)
        ankles = [(rot.T @ np.array(r["people"][k]["joints3d"][a]) + eye)[1] for r in records
                  for a in ("left_ankle", "right_ankle")]
        assert 0.02 < min(ankles) < 0.12
    # The waving person's root orientation is the built-in wave's turned 30 degrees about the vertical.
    world = rot.T @ quaternion_to_matrix(np.array(records[0]["people"][2]["pose"][3:7]))
    expected = axis_angle_matrix((0.0, 1.0, 0.0), np.radians(30.0)) @ builtin_motion("wave", 1, 30.0).root_rotation[0]
    np.testing.assert_allclose(world, expected, atol=1e-9)


@pytest.mark.slow
def test_rendered_depth_at_unoccluded_joints_is_the_persons_own_surface(scene):
    """Where a joint is not hidden by someone else, the noisy depth image shows the surface of
    that person's mesh cast alone (noise: ~2.6 cm disparity steps at 3 m)."""
    errors = []
    for r in _records(scene):
        depth = cv2.imread(str(scene / "depth" / f"{r['frame']:06d}.png"), cv2.IMREAD_UNCHANGED) / 1000.0
        for k, p in enumerate(r["people"]):
            for name in EVAL_JOINTS:
                if name in p["occluded"]:
                    continue
                u, v = (int(round(c)) for c in p["joints2d"][name])
                patch = np.array([(u + du, v + dv) for dv in (-1, 0, 1) for du in (-1, 0, 1)], float)
                own, who = _cast([_mesh(k, p)], patch)
                if np.any(who < 0) or np.ptp(own) > 0.03:
                    continue  # on the silhouette's edge: the depth there is not one surface
                seen = depth[v - 1:v + 2, u - 1:u + 2].ravel()
                if np.count_nonzero(seen) >= 5:
                    errors.append(abs(np.median(seen[seen > 0]) - np.median(own)))
    errors = np.array(errors)
    assert len(errors) >= 60
    assert np.median(errors) < 0.015 and np.mean(errors < 0.04) > 0.95


def test_occluded_joints_are_those_behind_another_persons_surface(scene):
    """The recorded ``occluded`` joints against a ray cast of all three meshes: a joint is hidden
    when the first surface along its pixel's ray is another person's, > 5 cm in front of it."""
    hidden_behind = 0
    for r in _records(scene):
        meshes = [_mesh(k, p) for k, p in enumerate(r["people"])]
        for k, p in enumerate(r["people"]):
            px = np.round(np.array([p["joints2d"][j] for j in EVAL_JOINTS]))
            t, who = _cast(meshes, px)
            z = np.array([p["joints3d"][j][2] for j in EVAL_JOINTS])
            expected = (who >= 0) & (who != k) & (t < z - MARGIN)
            borderline = np.abs(t - (z - MARGIN)) < 0.005
            recorded = np.array([j in p["occluded"] for j in EVAL_JOINTS])
            assert np.array_equal(recorded[~borderline], expected[~borderline]), (r["frame"], k)
            if k == FRONT:
                assert not recorded.any()
            if k == BEHIND:
                hidden_behind += int(recorded.sum())
    assert hidden_behind >= FRAMES  # the scene really hides part of person 2


def test_visible_share_and_box_match_a_ray_cast_of_everyone(scene):
    pixels = _all_pixels()
    for r in _records(scene):
        meshes = [_mesh(k, p) for k, p in enumerate(r["people"])]
        _, first = _cast(meshes, pixels)
        for k, p in enumerate(r["people"]):
            alone = np.count_nonzero(_cast([meshes[k]], pixels)[1] == 0)
            mine = (first == k).reshape(INTR.height, INTR.width)
            assert p["visible"] == pytest.approx(np.count_nonzero(mine) / alone, abs=0.005)
            rows, cols = np.flatnonzero(mine.any(1)), np.flatnonzero(mine.any(0))
            np.testing.assert_allclose(p["box"], [cols[0], rows[0], cols[-1], rows[-1]], atol=1)
        assert r["people"][FRONT]["visible"] > 0.99 and r["people"][2]["visible"] > 0.99
        assert 0.3 < r["people"][BEHIND]["visible"] < 0.95


def test_occluded_points_by_hand():
    """Person 1's points against a hand-made render: person 2 covers the left half at 2.0 m."""
    labels = np.zeros((4, 6), np.int32)
    labels[:, :3] = 2
    labels[:, 3:] = 1
    depth = np.full((4, 6), 2.0)
    points2d = np.array([[1.0, 1.0], [1.2, 2.4], [4.0, 1.0], [2.4, 0.0], [-1.0, 1.0], [1.0, 1.0]])
    z = np.array([2.3, 2.04, 3.0, 2.06, 3.0, -1.0])
    points3d = np.c_[np.zeros((6, 2)), z]
    hidden = occluded_points(points3d, points2d, depth, labels, person=1)
    # 30 cm behind person 2: hidden; 4 cm: within the margin; own pixel; 6 cm behind person 2
    # (pixel rounds to column 2); outside the image; behind the camera.
    assert hidden.tolist() == [True, False, False, True, False, False]
    # Seen as person 2's points, only the one on person 1's pixels, 1 m behind them, is hidden.
    assert occluded_points(points3d, points2d, depth, labels, person=2).tolist() == [False, False, True] + [False] * 3


def test_hidden_keypoints_are_missing_from_the_simulated_detections(scene):
    seen_total = present_total = 0
    for r in _records(scene):
        for p in r["people"]:
            for keypoint, point in zip(COCO17.keypoints, COCO17.points):
                if point not in EVAL_JOINTS:
                    continue
                score = p["detections"]["keypoints"][keypoint][2]
                if point in p["occluded"]:
                    assert score == 0.0, (r["frame"], p["id"], keypoint)
                else:
                    seen_total += 1
                    present_total += score > 0
    assert present_total / seen_total > 0.85  # the others stay (3 % dropped at random)


def test_each_persons_colour_differs(scene):
    colour = cv2.cvtColor(cv2.imread(str(scene / "color" / "000000.png")), cv2.COLOR_BGR2RGB).astype(float)
    r = _records(scene)[0]
    hues = []
    for p in r["people"]:
        x0, y0, x1, y1 = p["box"]
        u, v = (int(round(c)) for c in p["joints2d"]["right_hip" if p["id"] == 2 else "neck"])
        assert x0 <= u <= x1 and y0 <= v <= y1
        rgb = colour[v - 1:v + 2, u - 1:u + 2].reshape(-1, 3).mean(0)
        hues.append(rgb / rgb.sum())
    for a in range(3):
        for b in range(a + 1, 3):
            assert np.abs(hues[a] - hues[b]).max() > 0.08


def test_ground_truth_reads_every_person(scene):
    gt = load_ground_truth(scene)
    records = _records(scene)
    assert len(gt.people) == FRAMES
    for row, r in enumerate(records):
        people = gt.people_at(row)
        assert [p.id for p in people] == [1, 2, 3]
        np.testing.assert_array_equal(gt.poses[row], people[0].pose)
        np.testing.assert_array_equal(gt.detections[row][1], people[0].detection[1])
        for p, rec in zip(people, r["people"]):
            np.testing.assert_array_equal(p.pose, rec["pose"])
            np.testing.assert_array_equal(p.joints3d, [rec["joints3d"][j] for j in EVAL_JOINTS])
            np.testing.assert_array_equal(p.joints2d, [rec["joints2d"][j] for j in EVAL_JOINTS])
            np.testing.assert_array_equal(p.detection[1], [rec["detections"]["keypoints"][k] for k in COCO17.keypoints])
            assert p.visible == rec["visible"] and list(p.box) == rec["box"]
            assert [j for j, o in zip(EVAL_JOINTS, p.occluded) if o] == rec["occluded"]


@pytest.mark.parametrize(("change", "says"), [
    (lambda p: p.pop("visible"), "'visible'"),
    (lambda p: p.update(visible=1.5), "outside 0..1"),
    (lambda p: p.update(occluded=["tail"]), "unknown occluded joints"),
    (lambda p: p.update(pose=[0.0] * 35), "reshape"),
    (lambda p: p.update(id=1), "repeated person ids"),
])
def test_a_bad_person_entry_names_the_file_and_line(scene, tmp_path, change, says):
    lines = (scene / "groundtruth.jsonl").read_text().splitlines()
    broken = json.loads(lines[1])
    change(broken["people"][1])
    lines[1] = json.dumps(broken)
    (tmp_path / "groundtruth.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(AssetError, match=r"groundtruth.jsonl:2: not a ground-truth record") as info:
        load_ground_truth(tmp_path)
    assert says in str(info.value)


def _frame(row: int) -> Frame:
    return Frame(row, row * 33_333_333, np.zeros((INTR.height, INTR.width), np.float32), None, INTR)


def test_simulated_detector_returns_the_person_the_box_is_around(scene):
    gt = load_ground_truth(scene)
    detector = SimulatedDetector(gt, "people")
    for row in range(FRAMES):
        people = gt.people_at(row)
        for p in people:
            got = detector.detect(_frame(row), np.asarray(p.box, float))
            np.testing.assert_array_equal(got.keypoints, p.detection[1])
            # A box drawn around the person's true joints (not its pixels) picks it too.
            j2 = p.joints2d[~p.occluded]
            around = np.r_[j2.min(0) - 10, j2.max(0) + 10]
            np.testing.assert_array_equal(detector.detect(_frame(row), around).keypoints, p.detection[1])
        np.testing.assert_array_equal(detector.detect(_frame(row)).keypoints, people[0].detection[1])
        assert not np.any(detector.detect(_frame(row), np.array([0.0, 0.0, 20.0, 20.0])).keypoints)
        assert [(i, j.keypoints.tolist()) for i, j in detector.detect_people(_frame(row))] == \
            [(p.id, p.detection[1].tolist()) for p in people]


@pytest.fixture(scope="module")
def single(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("single")
    synthesize(_body("male").tracking_lod(1500), builtin_motion("wave", 2, 30.0), out, SynthConfig(frames=2),
               progress=False)
    return out


def test_single_person_files_keep_their_format_and_reading(single):
    records = _records(single)
    assert all(set(r) == {"frame", "timestamp_ns", "pose", "joints3d", "joints2d", "detections"} for r in records)
    assert "people" not in json.loads((single / "sequence.json").read_text())
    gt = load_ground_truth(single)
    assert gt.people == ((), ()) and gt.people_at(1) == ()
    np.testing.assert_array_equal(gt.poses[1], records[1]["pose"])
    detector = SimulatedDetector(gt, "single")
    far = detector.detect(_frame(1), np.array([0.0, 0.0, 5.0, 5.0])).keypoints
    np.testing.assert_array_equal(far, [records[1]["detections"]["keypoints"][k] for k in COCO17.keypoints])
    assert [i for i, _ in detector.detect_people(_frame(1))] == [1]


@pytest.mark.parametrize(("spec", "expected"), [
    ("builtin:female:builtin:walk", ("builtin", "female", "builtin:walk", 0.0, 0.0, 0.0, 0.0)),
    ("builtin::builtin:wave@1.5,-2", ("builtin", None, "builtin:wave", 1.5, -2.0, 0.0, 0.0)),
    ("makehuman:/data/mh:male-heavy:/clips/a.bvh@-1,0.5,90,4.5",
     ("makehuman:/data/mh", "male-heavy", "/clips/a.bvh", -1.0, 0.5, 90.0, 4.5)),
    ("/bodies/me@home.glb::builtin:squat@0,1,-45",
     ("/bodies/me@home.glb", None, "builtin:squat", 0.0, 1.0, -45.0, 0.0)),
])
def test_person_specs_parse(spec, expected):
    p = parse_person_spec(spec)
    assert (p.body, p.shape, p.motion, p.x, p.z, p.yaw_deg, p.start_s) == expected


@pytest.mark.parametrize(("spec", "says"), [
    ("builtin:walk", "no motion"),
    ("makehuman:/data/mh:male", "makehuman needs"),
    ("robot:default:builtin:walk", "unknown body 'robot'"),
    ("builtin::builtin:walk@1", "placement after '@'"),
    ("builtin::builtin:walk@1,x", "placement after '@'"),
    ("builtin::builtin:walk@99,0", "within ±20 m"),
    ("builtin::builtin:walk@0,0,0,-1", "start must be a non-negative"),
])
def test_bad_person_specs_name_the_spec_and_the_fix(spec, says):
    with pytest.raises(ConfigError, match="BODY:SHAPE:MOTION|within|start|unknown body") as info:
        parse_person_spec(spec)
    assert says in str(info.value) and repr(spec) in str(info.value)


def test_scenes_that_cannot_be_filmed_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="people 1 and 2 start 0.10 m apart"):
        load_people([parse_person_spec("builtin::builtin:walk@0,0"), parse_person_spec("builtin::builtin:walk@0.1,0")],
                    2, 30.0)
    with pytest.raises(ConfigError, match="1 to 6 people"):
        load_people([parse_person_spec(f"builtin::builtin:walk@{k},0") for k in range(7)], 2, 30.0)
    bad = tmp_path / "scene.json"
    bad.write_text(json.dumps([{"body": "builtin", "motion": "builtin:walk", "x": "left"}]))
    with pytest.raises(ConfigError, match=r"person 1: 'x' must be a number"):
        load_scene_file(bad)
    bad.write_text(json.dumps([{"body": "builtin", "moves": "builtin:walk"}]))
    with pytest.raises(ConfigError, match="unknown keys"):
        load_scene_file(bad)


def test_cli_scene_file_equals_person_flags_and_bad_specs_exit_2(tmp_path, capsys):
    from swarmpose.cli.main import main

    specs = ["builtin:female:builtin:walk@-0.4,0", "builtin:male:builtin:squat@0.5,-0.5,20"]
    (tmp_path / "scene.json").write_text(json.dumps([
        {"body": "builtin", "shape": "female", "motion": "builtin:walk", "x": -0.4, "z": 0},
        {"body": "builtin", "shape": "male", "motion": "builtin:squat", "x": 0.5, "z": -0.5, "yaw": 20}]))
    common = ["--frames", "1", "--quiet"]
    assert main(["synth", *sum((["--person", s] for s in specs), []), "--out", str(tmp_path / "a"), *common]) == 0
    assert main(["synth", "--scene", str(tmp_path / "scene.json"), "--out", str(tmp_path / "b"), *common]) == 0
    for name in ("groundtruth.jsonl", "depth/000000.png", "color/000000.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    capsys.readouterr()
    assert main(["synth", "--person", "builtin:walk", "--out", str(tmp_path / "c"), *common]) == 2
    assert "'builtin:walk' has no motion" in capsys.readouterr().err
    assert main(["synth", "--person", specs[0], "--motion", "builtin:wave", "--out", str(tmp_path / "c"), *common]) == 2
    assert "describe a single person" in capsys.readouterr().err
    assert main(["synth", "--out", str(tmp_path / "c"), *common]) == 2
    assert "needs --motion" in capsys.readouterr().err


@pytest.mark.slow
@needs_assets
def test_makehuman_walkers_cross_from_real_mocap(tmp_path):
    """Two MakeHuman walkers (CMU clip from 4.5 s, turned ±90°) cross in front of each other."""
    clip = MOCAP / "bvh11_131_01.bvh"
    people = load_people([parse_person_spec(f"makehuman:{MAKEHUMAN}:male:{clip}@-1.1,-0.8,90,4.5"),
                          parse_person_spec(f"makehuman:{MAKEHUMAN}:female:{clip}@1.0,0.4,-90,4.5")], 31, 30.0)
    config = SynthConfig(frames=31, camera_distance=3.5)
    synthesize_people(people, tmp_path, config, progress=False)
    records = _records(tmp_path)
    meta = json.loads((tmp_path / "sequence.json").read_text())
    rot, eye = np.array(meta["camera"]["world_to_camera_rotation"]), np.array(meta["camera"]["eye_world_m"])
    for k, start in enumerate(([-1.1, -0.8], [1.0, 0.4])):  # mid-clip, the root still starts where asked
        assert (rot.T @ np.array(records[0]["people"][k]["pose"][:3]) + eye)[[0, 2]] == pytest.approx(start, abs=1e-9)
    necks = np.array([[p["joints2d"]["neck"][0] for p in r["people"]] for r in records])
    assert necks[0, 0] < necks[0, 1] and necks[-1, 0] > necks[-1, 1]  # they swapped sides
    assert min(r["people"][0]["visible"] for r in records) < 0.8  # the far walker was hidden a while
    assert all(r["people"][1]["visible"] > 0.99 for r in records)  # the near one never
