"""`swarmpose synth` output: complete, readable by Open3D, consistent with its ground truth, seeded."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP, needs_assets

from swarmpose.body.skeleton import COCO17, EVAL_JOINTS
from swarmpose.cli.main import main


def _synth(out: Path, *extra: str) -> None:
    args = ["synth", "--body", "builtin", "--motion", "builtin:squat", "--frames", "4", "--out", str(out), "--quiet"]
    assert main(args + list(extra)) == 0


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("seq")
    _synth(out, "--seed", "3")
    return out


def _records(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "groundtruth.jsonl").read_text().splitlines()]


def test_folder_is_complete_and_open3d_reads_it(sequence):
    import open3d as o3d

    for i in range(4):
        colour = cv2.imread(str(sequence / "color" / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(sequence / "depth" / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        assert colour.shape == (480, 640, 3) and colour.dtype == np.uint8
        assert depth.shape == (480, 640) and depth.dtype == np.uint16
    intr = o3d.io.read_pinhole_camera_intrinsic(str(sequence / "intrinsic.json"))
    assert (intr.width, intr.height) == (640, 480)
    np.testing.assert_allclose(intr.intrinsic_matrix, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.io.read_image(str(sequence / "color" / "000000.png")),
        o3d.io.read_image(str(sequence / "depth" / "000000.png")),
        depth_scale=1000.0, depth_trunc=10.0, convert_rgb_to_intensity=False)
    cloud = o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, intr)
    assert len(cloud.points) > 100_000
    records = _records(sequence)
    assert [r["frame"] for r in records] == [0, 1, 2, 3]
    for r in records:
        assert set(r["joints3d"]) == set(EVAL_JOINTS) == set(r["joints2d"])
        assert len(r["pose"]) == 36
        assert r["detections"]["layout"] == "coco17" and list(r["detections"]["keypoints"]) == list(COCO17.keypoints)
    meta = json.loads((sequence / "sequence.json").read_text())
    assert meta["frames"] == 4 and meta["seed"] == 3 and meta["depth_noise"]["axial_a"] == 0.0012


def test_joints2d_are_the_pinhole_projection_of_joints3d(sequence):
    for r in _records(sequence):
        for name in EVAL_JOINTS:
            x, y, z = r["joints3d"][name]
            u, v = r["joints2d"][name]
            assert u == pytest.approx(525 * x / z + 319.5, abs=2e-3)
            assert v == pytest.approx(525 * y / z + 239.5, abs=2e-3)


def test_depth_image_agrees_with_ground_truth_joints(sequence):
    """The ray-cast depth (Open3D) and the ground-truth joints (numpy FK) describe the same body:
    at the pixel of a torso joint the measured surface lies a few centimetres in front of it."""
    for r in _records(sequence):
        depth = cv2.imread(str(sequence / "depth" / f"{r['frame']:06d}.png"), cv2.IMREAD_UNCHANGED) / 1000.0
        gaps = []
        for name in ("neck", "left_hip", "right_hip", "left_shoulder", "right_shoulder"):
            u, v = (int(round(c)) for c in r["joints2d"][name])
            patch = depth[v - 2:v + 3, u - 2:u + 3]
            patch = patch[patch > 0]
            if patch.size:
                gaps.append(r["joints3d"][name][2] - np.median(patch))
        assert len(gaps) >= 3
        assert 0.0 < np.median(gaps) < 0.2


def test_same_seed_same_sequence_other_seed_other_noise(tmp_path, sequence):
    _synth(tmp_path / "a", "--seed", "3")
    _synth(tmp_path / "b", "--seed", "4")
    for name in ("depth/000002.png", "color/000002.png", "groundtruth.jsonl"):
        assert (tmp_path / "a" / name).read_bytes() == (sequence / name).read_bytes()
    assert (tmp_path / "b" / "depth/000002.png").read_bytes() != (sequence / "depth/000002.png").read_bytes()
    assert (tmp_path / "b" / "color/000002.png").read_bytes() == (sequence / "color/000002.png").read_bytes()


def test_body_stands_on_the_floor(sequence):
    """The lowest ground-truth ankle over the sequence sits a few cm above the floor plane."""
    meta = json.loads((sequence / "sequence.json").read_text())
    rot = np.array(meta["camera"]["world_to_camera_rotation"])
    eye = np.array(meta["camera"]["eye_world_m"])
    heights = [(rot.T @ np.array(r["joints3d"][a]) + eye)[1] for r in _records(sequence)
               for a in ("left_ankle", "right_ankle")]
    assert 0.02 < min(heights) < 0.12


@needs_assets
def test_makehuman_subject_with_cmu_walk(tmp_path):
    out = tmp_path / "walk"
    assert main(["synth", "--body", f"makehuman:{MAKEHUMAN}", "--shape", "female", "--motion",
                 str(MOCAP / "bvh11_131_01.bvh"), "--frames", "3", "--out", str(out), "--quiet"]) == 0
    depth = cv2.imread(str(out / "depth" / "000002.png"), cv2.IMREAD_UNCHANGED) / 1000.0
    r = _records(out)[2]
    u, v = (int(round(c)) for c in r["joints2d"]["neck"])
    assert abs(np.median(depth[v - 3:v + 4, u - 3:u + 4]) - 3.0) < 0.5  # the person is ~3 m away


NEW_FAMILY_CLIPS = ["cmu_02_06_bend_scoop_pickup", "cmu_06_10_dribble_walk_left_turns", "cmu_09_01_run",
                    "cmu_10_01_soccer_kick", "cmu_14_31_sit_stepstool_standup", "cmu_135_04_front_kick"]


@needs_assets
@pytest.mark.parametrize("clip", [
    pytest.param(c, marks=pytest.mark.xfail(strict=True, reason="a deep crouch puts the body's foot 7 cm below "
                                            "its standing height (angles retarget, foot contact does not), so "
                                            "the standing frames float")) if c.startswith("cmu_02_06") else c
    for c in NEW_FAMILY_CLIPS])
def test_a_clip_of_the_new_families_stands_upright_on_the_floor_at_full_height(makehuman_male, clip):
    """Placed as synth places it (the whole clip's lowest sole on the floor), the first frame (a
    person standing: a T-pose in the Daz release) has a sole on the floor, the body's full height
    and an upright torso; the stool clip's hips go down to the seat as the README says (0.84 ->
    0.40 m in the clip, in proportion on the body)."""
    from swarmpose.motion.library import load_motion_spec
    from swarmpose.sim.scene import place_in_world

    body = makehuman_male
    motion = load_motion_spec(str(MOCAP / f"{clip}.bvh"), body, 0, 5.0)
    placed = place_in_world(body, motion, len(motion), skinning="lbs")
    first = body.pose(placed.poses[:1], "lbs")[0]
    assert first[:, 1].min() < 0.03
    assert abs(first[:, 1].max() - body.height) < 0.03 * body.height
    points = body.posed_points(placed.poses, ["mid_hip", "neck"])
    torso = points[0, 1] - points[0, 0]
    assert np.degrees(np.arccos(torso[1] / np.linalg.norm(torso))) < 10.0
    if clip.startswith("cmu_14_31"):
        hips = points[:, 0, 1]
        assert abs(hips.min() / hips[0] - 0.40 / 0.84) < 0.06
