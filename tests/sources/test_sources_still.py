"""`rgbd:` still frames, on the project's real Kinect v1 frame of five people walking down a corridor."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from conftest import ASSETS, needs_assets
from skimage import io as skio

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.sources.registry import open_source
from swarmpose.sources.still import StillSource

FIVE = ASSETS / "rgbd" / "kinect_five_people"
URI = (f"rgbd:{FIVE / 'five_people_color.png'},{FIVE / 'five_people_depth_mm.png'},"
       f"{FIVE / 'five_people_intrinsics.json'}")


@pytest.fixture(scope="module")
def frame():
    with open_source(URI) as src:
        assert isinstance(src, StillSource) and src.length == 1
        frames = list(src)
        assert src.status == "ended"
    assert len(frames) == 1
    return frames[0]


@needs_assets
def test_depth_in_metres_colour_rgb_and_flat_intrinsics(frame):
    """Depth = the PNG's millimetres (read by scikit-image) / 1000; 77.8 % of the pixels valid, from
    1.76 m (the nearest person's back) to 9.76 m (the corridor's end); colour as scikit-image reads it."""
    raw = skio.imread(FIVE / "five_people_depth_mm.png")
    assert raw.dtype == np.uint16
    np.testing.assert_array_equal(frame.depth, raw.astype(np.float32) / np.float32(1000.0))
    np.testing.assert_array_equal(frame.color, skio.imread(FIVE / "five_people_color.png")[..., :3])
    valid = frame.depth[frame.depth > 0]
    assert valid.size / frame.depth.size == pytest.approx(0.778, abs=0.002)
    assert 1.7 < valid.min() < 1.8 and 9.5 < valid.max() < 10.0
    assert 2.3 < np.median(valid) < 2.8  # most pixels are the people and the floor in front of them
    k = json.loads((FIVE / "five_people_intrinsics.json").read_text())
    assert frame.intrinsics == Intrinsics(640, 480, k["fx"], k["fy"], k["cx"], k["cy"])
    assert frame.size == (640, 480) and frame.index == 0 and frame.timestamp_ns == 0


@needs_assets
def test_people_separate_from_the_floor(frame):
    """Back-project the frame, fit the floor with Open3D's RANSAC plane, drop it and cluster the rest
    with DBSCAN (3 cm voxels, eps 5 cm). Observed: the floor 1.28 m below the camera (normal along the
    camera's -y), and 4 clusters standing on it that are 1.71-1.81 m tall at 1.86-2.71 m: three single
    people 0.48-0.57 m wide and the two middle people walking shoulder to shoulder as one 0.98 m
    cluster. Heights of 1.7-1.8 m for people measured from a fitted floor confirm the metric scale
    of the depth and of the intrinsics together."""
    import open3d as o3d

    k = frame.intrinsics
    v, u = np.nonzero(frame.depth > 0)
    z = frame.depth[v, u].astype(np.float64)
    pts = np.column_stack([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).voxel_down_sample(0.03)
    o3d.utility.random.seed(0)
    plane, inliers = cloud.segment_plane(distance_threshold=0.03, ransac_n=3, num_iterations=500)
    normal, offset = np.asarray(plane[:3]), plane[3]
    if offset < 0:  # orient the plane so that the camera (the origin) is on its positive side
        normal, offset = -normal, -offset
    assert 1.2 < offset < 1.4  # camera height above the floor
    assert normal[1] < -0.95  # "up" is the camera's -y
    rest = cloud.select_by_index(inliers, invert=True)
    points = np.asarray(rest.points)
    height = points @ normal + offset
    above = np.flatnonzero(height > 0.05)
    points, height = points[above], height[above]
    labels = np.asarray(rest.select_by_index(above).cluster_dbscan(eps=0.05, min_points=10))
    people = []
    for c in range(labels.max() + 1):
        members = labels == c
        top, bottom = height[members].max(), height[members].min()
        width = np.ptp(points[members, 0])
        if 1.2 <= top <= 2.1 and bottom < 0.8 and width < 1.2:  # stands on the floor, person-tall
            people.append((top, float(np.median(points[members, 2])), width))
    assert len(people) == 4, people
    assert all(1.65 < top < 1.85 and 1.7 < dist < 3.0 for top, dist, _ in people)
    assert sorted(w < 0.7 for _, _, w in people) == [False, True, True, True]


@needs_assets
def test_open3d_json_intrinsics_and_millimetres_by_default(tmp_path):
    """An Open3D PinholeCameraIntrinsic file (no depth_scale) gives the same frame."""
    Intrinsics.kinect_v1().save(tmp_path / "k.json")
    src = open_source(f"rgbd:{FIVE / 'five_people_color.png'},{FIVE / 'five_people_depth_mm.png'},"
                      f"{tmp_path / 'k.json'}")
    (f,) = list(src)
    assert f.intrinsics == Intrinsics.kinect_v1()
    assert f.depth[240, 320] == pytest.approx(skio.imread(FIVE / "five_people_depth_mm.png")[240, 320] / 1000)


@needs_assets
def test_bad_still_sources(tmp_path):
    with pytest.raises(ConfigError, match="three comma-separated files"):
        open_source(f"rgbd:{FIVE / 'five_people_color.png'},{FIVE / 'five_people_depth_mm.png'}")
    with pytest.raises(SourceError, match="intrinsics file .*missing.json is missing"):
        open_source(f"rgbd:{FIVE / 'five_people_color.png'},{FIVE / 'five_people_depth_mm.png'},"
                    f"{tmp_path / 'missing.json'}")
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((240, 320, 3), np.uint8))
    with pytest.raises(SourceError, match="depth 640x480 and colour 320x240 differ in size"):
        open_source(f"rgbd:{small},{FIVE / 'five_people_depth_mm.png'},{FIVE / 'five_people_intrinsics.json'}")
    with pytest.raises(SourceError, match="expected single-channel uint16"):
        open_source(f"rgbd:{FIVE / 'five_people_color.png'},{FIVE / 'five_people_color.png'},"
                    f"{FIVE / 'five_people_intrinsics.json'}")
