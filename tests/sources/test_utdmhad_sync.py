"""UTD-MHAD's skeleton in time with its depth: the interpolation by hand, the lag against the
real depth (the oracle: the Kinect's own depth under the projected joints), the source's option."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ASSETS, needs_assets
from scipy.io import savemat

from swarmpose.core.errors import ConfigError
from swarmpose.sources.registry import open_source
from swarmpose.sources.utdmhad import KINECT_JOINTS, UtdMhadSource
from swarmpose.sources.utdmhad_sync import AGREEMENT_JOINTS, DEPTH_LAG_FRAMES, depth_agreement_mm, synchronised

UTD = ASSETS / "rgbd" / "utd_mhad" / "depth"


def test_the_skeleton_is_interpolated_lag_frames_back_and_held_at_the_start():
    skeleton = np.arange(5 * 2 * 3, dtype=float).reshape(5, 2, 3)
    skeleton[3, 1] = np.nan
    np.testing.assert_array_equal(synchronised(skeleton, 0.0), skeleton)
    shifted = synchronised(skeleton, 1.75)
    np.testing.assert_allclose(shifted[0], skeleton[0])  # t - lag < 0: held at the first frame
    np.testing.assert_allclose(shifted[1], skeleton[0])
    np.testing.assert_allclose(shifted[2], 0.75 * skeleton[0] + 0.25 * skeleton[1])
    np.testing.assert_allclose(shifted[3, 0], 0.75 * skeleton[1, 0] + 0.25 * skeleton[2, 0])
    assert np.all(np.isfinite(shifted[4, 0])) and np.all(np.isnan(shifted[4, 1]))  # a neighbour untracked


@needs_assets
@pytest.mark.parametrize("name", ["a13_s1_t1", "a5_s2_t1", "a14_s3_t1"])
def test_the_depth_trails_the_skeleton_by_the_measured_lag(name):
    """Boxing, a throw and a baseball swing, one per subject: the skeleton's moving joints agree
    with the depth under them best between 1 and 2.5 frames back, and the measured lag beats the
    files' pairing (the module doc's 81-sequence figures: 59.7 against 67.9 mm)."""
    source = UtdMhadSource(UTD / f"{name}_depth.mat")
    joints = [KINECT_JOINTS.index(j) for j in AGREEMENT_JOINTS]
    lags = np.arange(-1.0, 4.01, 0.25)
    gaps = depth_agreement_mm(source.depth, source.skeleton, joints, source.intrinsics, lags)
    assert 1.0 <= lags[int(np.argmin(gaps))] <= 2.5, dict(zip(lags, gaps.round(1)))
    at_lag, paired = depth_agreement_mm(source.depth, source.skeleton, joints, source.intrinsics,
                                        [DEPTH_LAG_FRAMES, 0.0])
    assert at_lag < paired - 1.0, (at_lag, paired)


def _files(folder, frames=4):
    (folder / "depth").mkdir()
    (folder / "skeleton").mkdir()
    depth = np.zeros((240, 320, frames), np.uint16)
    depth[100:140, 150:170] = 3000
    skeleton = np.tile(np.array([0.1, 0.2, 3.0]), (20, 1))[:, :, None].repeat(frames, axis=2)
    skeleton[[0, 6], 0, :] += 0.1 * np.arange(frames)  # the head and left wrist move along x, 10 cm a frame
    savemat(str(folder / "depth" / "a1_s1_t1_depth.mat"), {"d_depth": depth})
    savemat(str(folder / "skeleton" / "a1_s1_t1_skeleton.mat"), {"d_skel": skeleton})
    return folder / "depth" / "a1_s1_t1_depth.mat"


def test_the_source_compares_depth_with_the_skeleton_lag_frames_back(tmp_path):
    path = _files(tmp_path)
    x_of, wrist_px = {}, {}
    for uri in (f"utdmhad:{path}", f"utdmhad:{path}?lag=0", f"utdmhad:{path}?lag=1"):
        with open_source(uri) as source:
            x_of[uri.partition("?")[2]] = source.ground_truth.joints3d[:, 0, 0]
            wrist_px[uri.partition("?")[2]] = np.array([p["left_wrist"] for p in source.ground_truth.points2d])
    kinect_x = -(0.1 + 0.1 * np.arange(4))  # the Kinect's x points to the sensor's left: ours is -x
    np.testing.assert_allclose(x_of["lag=0"], kinect_x)
    np.testing.assert_allclose(x_of["lag=1"], kinect_x[[0, 0, 1, 2]])
    np.testing.assert_allclose(x_of[""], [kinect_x[0], kinect_x[0], 0.75 * kinect_x[0] + 0.25 * kinect_x[1],
                                          0.75 * kinect_x[1] + 0.25 * kinect_x[2]])  # the default, 1.75 back
    # the simulated detector's keypoints move with the ground truth: the wrist's pixel by hand
    intr = UtdMhadSource(path).intrinsics
    for key, x in x_of.items():
        wrist = np.column_stack([x, np.full(4, -0.2), np.full(4, 3.0)])  # Kinect (x, 0.2, 3) in our frame
        np.testing.assert_allclose(wrist_px[key], intr.project(wrist), atol=1e-9)


def test_a_bad_lag_is_refused_naming_the_option(tmp_path):
    path = _files(tmp_path)
    with pytest.raises(ConfigError, match=r"\?lag=FRAMES"):
        open_source(f"utdmhad:{path}?shift=2")
    with pytest.raises(ConfigError, match=r"\?lag=FRAMES"):
        open_source(f"utdmhad:{path}?lag=soon")
    with pytest.raises(ConfigError, match="lag=-1 for .*a1_s1_t1_depth.mat is not a number of frames within 0..10"):
        open_source(f"utdmhad:{path}?lag=-1")
    with pytest.raises(ConfigError, match="not a number of frames"):
        open_source(f"utdmhad:{path}?lag=nan")
