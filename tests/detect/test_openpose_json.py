"""OpenPose --write_json files (hand-built, BODY_25 and COCO-18) read back as Joints2D."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from swarmpose.body.skeleton import LAYOUTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import DetectorError
from swarmpose.detect.openpose_json import OpenPoseJsonDetector
from swarmpose.sources.base import Frame

INTR = Intrinsics.kinect_v1()


def _frame(index: int, timestamp_ns: int = 0) -> Frame:
    return Frame(index, timestamp_ns, np.zeros((480, 640), np.float32), None, INTR)


def _write(folder: Path, number: int, people: list[list[float]], name: str = "clip") -> Path:
    """One file as OpenPose writes it (version 1.3 layout, with the face/hand arrays empty)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}_{number:012d}_keypoints.json"
    path.write_text(json.dumps({"version": 1.3, "people": [
        {"person_id": [-1], "pose_keypoints_2d": p, "face_keypoints_2d": [], "hand_left_keypoints_2d": [],
         "hand_right_keypoints_2d": [], "pose_keypoints_3d": [], "face_keypoints_3d": [],
         "hand_left_keypoints_3d": [], "hand_right_keypoints_3d": []} for p in people]}))
    return path


def _person(count: int, x0: float, conf: float) -> list[float]:
    """Keypoint k at (x0 + 10 k, 200 + k), confidence ``conf``; keypoint 3 missing (0, 0, 0)."""
    flat = []
    for k in range(count):
        flat += [0.0, 0.0, 0.0] if k == 3 else [x0 + 10 * k, 200.0 + k, conf]
    return flat


def test_body25_file_with_two_people_gives_the_most_confident(tmp_path):
    _write(tmp_path, 0, [_person(25, 100, 0.4), _person(25, 300, 0.8)])
    det = OpenPoseJsonDetector(tmp_path)
    assert det.layout.name == "body25"
    j = det.detect(_frame(0, 123))
    assert (j.frame_index, j.timestamp_ns) == (0, 123)
    assert j.keypoints.shape == (25, 3)
    assert j.keypoints[0].tolist() == [300.0, 200.0, 0.8]
    assert j.keypoints[24].tolist() == [540.0, 224.0, 0.8]
    assert j.keypoints[3].tolist() == [0.0, 0.0, 0.0]
    # BODY_25 order: 4 = right wrist, 8 = mid hip, 19 = left big toe (the body's left toe)
    by_point = j.by_point()
    assert by_point["right_wrist"] == (340.0, 204.0, 0.8)
    assert by_point["mid_hip"] == (380.0, 208.0, 0.8)
    assert by_point["left_toe"] == (490.0, 219.0, 0.8)
    assert "right_elbow" not in by_point  # keypoint 3 was missing


def test_a_box_picks_the_closest_person(tmp_path):
    _write(tmp_path, 0, [_person(25, 100, 0.4), _person(25, 300, 0.8)])
    det = OpenPoseJsonDetector(tmp_path)
    j = det.detect(_frame(0), box=np.array([80, 150, 360, 260]))  # centre (220, 205): person 1 spans 100..340
    assert j.keypoints[0].tolist() == [100.0, 200.0, 0.4]


def test_coco18_files_use_openpose_order(tmp_path):
    _write(tmp_path, 0, [_person(18, 50, 0.9)])
    det = OpenPoseJsonDetector(tmp_path)
    assert det.layout is LAYOUTS["openpose18"]
    j = det.detect(_frame(0))
    assert j.keypoints.shape == (18, 3)
    by_point = j.by_point()
    # OpenPose COCO-18: 0 nose, 1 neck, 2 r_sho, 4 r_wri, 8 r_hip, 11 l_hip, 13 l_ank, 14 r_eye, 17 l_ear
    assert by_point["nose"][:2] == (50.0, 200.0)
    assert by_point["neck"][:2] == (60.0, 201.0)
    assert by_point["right_shoulder"][:2] == (70.0, 202.0)
    assert by_point["right_wrist"][:2] == (90.0, 204.0)
    assert by_point["right_hip"][:2] == (130.0, 208.0)
    assert by_point["left_hip"][:2] == (160.0, 211.0)
    assert by_point["left_ankle"][:2] == (180.0, 213.0)
    assert by_point["right_eye"][:2] == (190.0, 214.0)
    assert by_point["left_ear"][:2] == (220.0, 217.0)


def test_frames_follow_the_number_in_the_name_and_gaps_are_all_missing(tmp_path):
    _write(tmp_path, 0, [_person(25, 10, 0.9)])
    _write(tmp_path, 2, [_person(25, 30, 0.9)])
    _write(tmp_path, 3, [])  # OpenPose found nobody
    det = OpenPoseJsonDetector(tmp_path)
    assert det.detect(_frame(0)).keypoints[0, 0] == 10.0
    assert det.detect(_frame(2)).keypoints[0, 0] == 30.0
    for missing in (1, 3, 4):
        j = det.detect(_frame(missing))
        assert j.keypoints.shape == (25, 3) and np.all(j.keypoints == 0)


def test_unnumbered_files_are_taken_in_sorted_order(tmp_path):
    for name, x in (("b", 20), ("a", 10), ("c", 30)):
        (tmp_path / f"{name}_keypoints.json").write_text(json.dumps({"people": [{"pose_keypoints_2d":
                                                                                  _person(25, x, 0.5)}]}))
    det = OpenPoseJsonDetector(tmp_path)
    assert [det.detect(_frame(i)).keypoints[0, 0] for i in range(3)] == [10.0, 20.0, 30.0]


def test_malformed_files_raise_naming_the_file(tmp_path):
    _write(tmp_path, 0, [_person(25, 10, 0.9)])
    bad = tmp_path / "clip_000000000001_keypoints.json"
    bad.write_text('{"people": [{"pose_keypoints_2d": [1, 2')
    wrong_count = _write(tmp_path, 2, [[1.0, 2.0, 0.5] * 17])
    no_people = tmp_path / "clip_000000000003_keypoints.json"
    no_people.write_text('{"version": 1.3}')
    det = OpenPoseJsonDetector(tmp_path)
    assert det.layout.name == "body25"
    for index, path, what in ((1, bad, "not OpenPose"), (2, wrong_count, "51 values"), (3, no_people, "people")):
        with pytest.raises(DetectorError, match=what) as err:
            det.detect(_frame(index))
        assert str(path) in str(err.value)
    assert det.detect(_frame(0)).keypoints[0, 0] == 10.0


def test_a_coco18_person_in_a_body25_folder_is_an_error(tmp_path):
    _write(tmp_path, 0, [_person(25, 10, 0.9)])
    path = _write(tmp_path, 1, [_person(18, 10, 0.9)])
    with pytest.raises(DetectorError, match="18 keypoints.*body25") as err:
        OpenPoseJsonDetector(tmp_path).detect(_frame(1))
    assert str(path) in str(err.value)


def test_missing_or_empty_folders_are_refused(tmp_path):
    with pytest.raises(DetectorError, match="not found"):
        OpenPoseJsonDetector(tmp_path / "absent")
    with pytest.raises(DetectorError, match="no OpenPose"):
        OpenPoseJsonDetector(tmp_path)


def test_a_folder_where_nobody_was_found_defaults_to_body25_or_the_given_layout(tmp_path):
    _write(tmp_path, 0, [])
    assert OpenPoseJsonDetector(tmp_path).layout.name == "body25"
    det = OpenPoseJsonDetector(tmp_path, layout="openpose18")
    assert det.detect(_frame(0)).keypoints.shape == (18, 3)
    with pytest.raises(DetectorError, match="layout"):
        OpenPoseJsonDetector(tmp_path, layout="coco17")
