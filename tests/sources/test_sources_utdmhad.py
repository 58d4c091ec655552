"""``utdmhad:`` source: real Kinect v1 depth of real people (UTD-MHAD) with the Kinect skeleton."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ASSETS, needs_assets
from scipy.io import savemat

from swarmpose.core.errors import SourceError
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source
from swarmpose.sources.utdmhad import INTRINSICS, KINECT_JOINTS, UtdMhadSource, measured_height

UTD = ASSETS / "rgbd" / "utd_mhad"
A1_S1 = UTD / "depth" / "a1_s1_t1_depth.mat"


@needs_assets
def test_a_utdmhad_file_opens_with_its_skeleton_and_every_frame():
    with open_source(f"utdmhad:{A1_S1}") as source:
        frames = [f for f in source if isinstance(f, Frame)]
        assert source.length == len(frames) == 48 == len(source.ground_truth.frames)
        first = frames[0]
        assert first.depth.shape == (240, 320) and first.depth.dtype == np.float32
        assert first.color.shape == (240, 320, 3) and first.color.dtype == np.uint8
        assert first.intrinsics == INTRINSICS
        assert frames[1].timestamp_ns - first.timestamp_ns == pytest.approx(33_333_333)
        person = first.depth > 0
        assert 2.5 < np.median(first.depth[person]) < 3.5  # the subject stands about 3 m away
        assert np.all(first.color[~person] == 0) and np.median(first.color[person, 0]) > 40
        # the skeleton lands on the person: the projected joints mostly hit depth pixels, and the
        # depth surface lies in front of the joints (by a few centimetres)
        hits, gaps = 0, []
        for frame in frames:
            joints = source.skeleton[frame.index]
            uv = np.round(INTRINSICS.project(joints)).astype(int)
            for (u, v), z in zip(uv, joints[:, 2]):
                if 0 <= u < 320 and 0 <= v < 240 and frame.depth[v, u] > 0:
                    hits += 1
                    gaps.append(z - frame.depth[v, u])
        assert hits / (len(frames) * len(KINECT_JOINTS)) > 0.9
        assert 0.02 < np.median(gaps) < 0.12


@needs_assets
def test_utdmhad_is_unmirrored_so_the_skeletons_left_is_the_networks_left():
    """MoveNet on the shaded depth finds each labelled shoulder, wrist and knee within 8 px of
    the Kinect joint of the same name (measured: 1-5 px); on the raw mirrored images the
    labels would swap (the two sides are 35 px apart)."""
    from swarmpose.detect.onnx_pose import OnnxPoseDetector

    source = UtdMhadSource(A1_S1)
    frame = next(iter(source))
    joints = OnnxPoseDetector(ASSETS / "pose2d" / "movenet_singlepose_lightning.onnx").detect(frame)
    truth = INTRINSICS.project(source.skeleton[0])
    for name in ("left_shoulder", "right_shoulder", "left_wrist", "right_wrist", "left_knee", "right_knee"):
        found = joints.keypoints[joints.layout.keypoints.index(name), :2]
        assert np.hypot(*(found - truth[KINECT_JOINTS.index(name)])) < 8, name


@needs_assets
def test_the_ground_truth_maps_kinect_joints_to_the_evaluation_joints():
    source = UtdMhadSource(A1_S1, lag_frames=0.0)  # the files' pairing (the lag: test_utdmhad_sync.py)
    truth = source.ground_truth
    assert truth.joints3d.shape == (48, 14, 3) and np.all(np.isfinite(truth.joints3d))
    raw = source.skeleton
    np.testing.assert_allclose(truth.joints3d[:, 1], raw[:, KINECT_JOINTS.index("shoulder_center")])
    np.testing.assert_allclose(truth.joints3d[:, 13], raw[:, KINECT_JOINTS.index("right_ankle")])
    # un-mirrored, y down: the head above the ankles, the person's left shoulder on the image's right
    assert np.all(truth.joints3d[:, 0, 1] < truth.joints3d[:, 12, 1] - 1.0)
    assert np.all(truth.joints3d[:, 2, 0] > truth.joints3d[:, 3, 0])


@needs_assets
def test_the_simulated_detector_draws_keypoints_from_the_kinect_skeleton():
    from swarmpose.detect.simulated import SimulatedDetector

    source = UtdMhadSource(A1_S1, lag_frames=0.0)
    detector = SimulatedDetector(source.ground_truth, "a1_s1")
    frames = list(source)
    found = [detector.detect(f) for f in frames[:10]]
    assert found[0].layout.name == "coco17"
    wrist = found[0].layout.keypoints.index("left_wrist")
    truth = INTRINSICS.project(source.skeleton[:10, KINECT_JOINTS.index("left_wrist")])
    gaps = [np.hypot(*(j.keypoints[wrist, :2] - t)) for j, t in zip(found, truth) if j.keypoints[wrist, 2] > 0]
    assert len(gaps) >= 8 and np.median(gaps) < 4  # jitter 1 % of a ~150 px person
    assert np.all(found[0].keypoints[:5] == 0)  # no face in a Kinect skeleton: nose, eyes, ears missing
    np.testing.assert_array_equal(detector.detect(frames[3]).keypoints, found[3].keypoints)  # seeded per frame


@needs_assets
def test_the_measured_height_is_stable_over_actions_and_tells_subjects_apart():
    """The first frame's depth of a standing subject: within 2 cm across actions, and below the
    Kinect skeleton's head-centre-to-ankle span + 0.25 m (head top and soles), above it."""
    heights = {}
    for subject in ("s1", "s2"):
        values = []
        for action in (1, 5, 23):
            source = UtdMhadSource(UTD / "depth" / f"a{action}_{subject}_t1_depth.mat")
            values.append(measured_height(source.depth[0]))
            skeleton = source.skeleton[0]
            span = skeleton[KINECT_JOINTS.index("head"), 1] - skeleton[KINECT_JOINTS.index("left_ankle"), 1]
            assert abs(span) < values[-1] < abs(span) + 0.25
        assert np.ptp(values) < 0.02
        heights[subject] = np.mean(values)
    assert heights["s1"] - heights["s2"] > 0.08


def _mat(path, **variables):
    savemat(str(path), variables)
    return path


def test_bad_utdmhad_input_is_refused_naming_the_file(tmp_path):
    depth_dir, skel_dir = tmp_path / "depth", tmp_path / "skeleton"
    depth_dir.mkdir()
    skel_dir.mkdir()
    depth = np.zeros((240, 320, 5), np.uint16)
    # not a MATLAB file
    junk = depth_dir / "a1_s9_t1_depth.mat"
    junk.write_bytes(b"not matlab at all")
    with pytest.raises(SourceError, match="a1_s9_t1_depth.mat.*MATLAB"):
        UtdMhadSource(junk)
    # a MATLAB file without d_depth
    other = _mat(depth_dir / "a2_s9_t1_depth.mat", something=np.ones(3))
    _mat(skel_dir / "a2_s9_t1_skeleton.mat", d_skel=np.zeros((20, 3, 5)))
    with pytest.raises(SourceError, match="no variable 'd_depth'"):
        UtdMhadSource(other)
    # no skeleton beside it
    lonely = _mat(depth_dir / "a3_s9_t1_depth.mat", d_depth=depth)
    with pytest.raises(SourceError, match="no skeleton file.*a3_s9_t1_skeleton.mat"):
        UtdMhadSource(lonely)
    # frame counts differ
    short = _mat(depth_dir / "a4_s9_t1_depth.mat", d_depth=depth)
    _mat(skel_dir / "a4_s9_t1_skeleton.mat", d_skel=np.zeros((20, 3, 4)))
    with pytest.raises(SourceError, match="5 depth frames but .* 4 skeletons"):
        UtdMhadSource(short)
    # wrong shapes
    wrong = _mat(depth_dir / "a5_s9_t1_depth.mat", d_depth=np.zeros((10, 10, 5), np.uint16))
    _mat(skel_dir / "a5_s9_t1_skeleton.mat", d_skel=np.zeros((20, 3, 5)))
    with pytest.raises(SourceError, match=r"d_depth .* is \(10, 10, 5\)"):
        UtdMhadSource(wrong)
    # a name that is not UTD-MHAD's
    renamed = _mat(tmp_path / "recording.mat", d_depth=depth)
    with pytest.raises(SourceError, match="not named like a UTD-MHAD depth file"):
        open_source(str(renamed))
    with pytest.raises(SourceError, match="does not exist"):
        open_source(f"utdmhad:{tmp_path / 'a1_s1_t1_depth.mat'}")


def test_untracked_kinect_joints_become_missing(tmp_path):
    """The Kinect writes a joint it did not track as (0, 0, 0): it is NaN in the ground truth,
    and the other joints keep their (converted) values."""
    (tmp_path / "depth").mkdir()
    (tmp_path / "skeleton").mkdir()
    depth = np.zeros((240, 320, 2), np.uint16)
    depth[100:140, 150:170] = 3000
    skeleton = np.tile(np.array([0.1, 0.2, 3.0]), (20, 1))[:, :, None].repeat(2, axis=2)
    skeleton[6, :, 1] = 0.0  # left_wrist untracked in frame 1
    _mat(tmp_path / "depth" / "a1_s1_t1_depth.mat", d_depth=depth)
    _mat(tmp_path / "skeleton" / "a1_s1_t1_skeleton.mat", d_skel=skeleton)
    source = UtdMhadSource(tmp_path / "depth" / "a1_s1_t1_depth.mat", lag_frames=0.0)
    np.testing.assert_allclose(source.skeleton[0, 6], [-0.1, -0.2, 3.0])
    assert np.all(np.isnan(source.skeleton[1, 6])) and np.all(np.isfinite(source.skeleton[1, 5]))
    truth = source.ground_truth.joints3d
    wrist = 6  # EVAL_JOINTS: head, neck, shoulders, elbows, then left_wrist
    assert np.all(np.isnan(truth[1, wrist])) and np.all(np.isfinite(truth[0]))
