"""Open3D-backed sources (`bag:`, `realsense:`, `azure:`): the errors without a device, library or
valid file, and the conversion of Open3D's RGBD images into frames, checked against Open3D itself.
No RealSense or Azure Kinect device and no .bag recording exist here: live capture and bag reading
are not exercised (see README, Frame sources)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ASSETS

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.sources.open3d_io import intrinsics_from_open3d, rgbd_to_frame
from swarmpose.sources.registry import open_source

o3d = pytest.importorskip("open3d")


def _images(h: int = 48, w: int = 64) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    depth = rng.integers(500, 4000, (h, w)).astype(np.uint16)
    depth[3:6, 4:9] = 0
    color = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)
    return depth, color


def test_tensor_rgbd_image_to_frame():
    """An open3d.t.geometry.RGBDImage (what RSBagReader and RealSenseSensor return): uint16 depth in
    units of 1/depth_scale m, colour RGB."""
    depth, color = _images()
    rgbd = o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3d.core.Tensor(color)),
                                    o3d.t.geometry.Image(o3d.core.Tensor(depth)))
    intr = Intrinsics(64, 48, 50.0, 51.0, 31.5, 23.5)
    frame = rgbd_to_frame(rgbd, intr, 4000.0, 7, 123)  # an L515-like 4000 units per metre
    np.testing.assert_allclose(frame.depth, depth / 4000.0, rtol=1e-6)
    assert frame.depth.dtype == np.float32 and frame.depth[4, 5] == 0
    np.testing.assert_array_equal(frame.color, color)
    assert (frame.index, frame.timestamp_ns, frame.intrinsics) == (7, 123, intr)


def test_legacy_rgbd_image_matches_open3d_point_cloud():
    """A legacy RGBDImage made by Open3D (float metres) becomes a frame whose back-projection with the
    converted intrinsics equals Open3D's own create_from_rgbd_image point cloud."""
    depth, color = _images()
    pinhole = o3d.camera.PinholeCameraIntrinsic(64, 48, 50.0, 51.0, 31.5, 23.5)
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(color), o3d.geometry.Image(depth), depth_scale=1000.0, depth_trunc=10.0,
        convert_rgb_to_intensity=False)
    intr = intrinsics_from_open3d(pinhole)
    assert intr == Intrinsics(64, 48, 50.0, 51.0, 31.5, 23.5)
    frame = rgbd_to_frame(rgbd, intr, 1000.0, 0, 0)  # float depth: already metres, the scale is unused
    np.testing.assert_allclose(frame.depth, depth / 1000.0, rtol=1e-6)
    reference = np.asarray(o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, pinhole).points)
    v, u = np.nonzero(frame.depth > 0)
    z = frame.depth[v, u]
    ours = np.column_stack([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])
    np.testing.assert_allclose(ours, reference, atol=1e-5)
    np.testing.assert_array_equal(frame.color, color)


def test_legacy_raw_depth_and_bgra_like_colour():
    """AzureKinectSensor's legacy images: raw uint16 millimetres; a 4th colour channel is dropped."""
    depth, color = _images()
    rgbd = o3d.geometry.RGBDImage()
    rgbd.depth = o3d.geometry.Image(depth)
    rgbd.color = o3d.geometry.Image(np.ascontiguousarray(np.dstack([color, np.full(depth.shape, 255, np.uint8)])))
    frame = rgbd_to_frame(rgbd, Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5), 1000.0, 0, 0)
    np.testing.assert_allclose(frame.depth, depth / 1000.0, rtol=1e-6)
    np.testing.assert_array_equal(frame.color, color)


def test_size_mismatches_are_errors():
    depth, color = _images()
    rgbd = o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3d.core.Tensor(color[:24, :32].copy())),
                                    o3d.t.geometry.Image(o3d.core.Tensor(depth)))
    with pytest.raises(SourceError, match="depth 64x48 and colour 32x24 differ"):
        rgbd_to_frame(rgbd, Intrinsics(64, 48, 50, 50, 31.5, 23.5), 1000.0, 0, 0)
    rgbd = o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3d.core.Tensor(color)),
                                    o3d.t.geometry.Image(o3d.core.Tensor(depth)))
    with pytest.raises(SourceError, match="intrinsics 640x480"):
        rgbd_to_frame(rgbd, Intrinsics.kinect_v1(), 1000.0, 0, 0)


def test_bag_errors(tmp_path):
    with pytest.raises(SourceError, match=r"bag: file .*none\.bag does not exist"):
        open_source(f"bag:{tmp_path / 'none.bag'}")
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 8)
    with pytest.raises(SourceError, match="not a readable RealSense recording"):
        open_source(f"bag:{garbage}")
    mkv = ASSETS / "rgbd" / "azure_kinect_one_frame" / "recording.mkv"
    if mkv.is_file():  # a real recording of another kind
        with pytest.raises(SourceError, match="bag: Open3D cannot read .*Unsupported file format"):
            open_source(f"bag:{mkv}")


def test_realsense_without_a_camera():
    if o3d.t.io.RealSenseSensor.enumerate_devices():
        pytest.skip("a RealSense camera is connected")
    with pytest.raises(SourceError, match="no RealSense camera is connected"):
        open_source("realsense:")
    with pytest.raises(SourceError, match="no RealSense camera is connected"):
        open_source("realsense:123456789012")


def _k4a_loads() -> bool:
    try:
        o3d.io.AzureKinectSensor.list_devices()
        return True
    except RuntimeError:
        return False


def test_azure_without_the_sdk():
    """Debian has no Azure Kinect SDK: Open3D cannot load libk4a.so, and the source says what to install."""
    if _k4a_loads():
        pytest.skip("the Azure Kinect SDK is installed")
    with pytest.raises(SourceError, match=r"libk4a\.so.*Azure Kinect Sensor SDK"):
        open_source("azure:")
    with pytest.raises(ConfigError, match="device index must be an integer"):
        open_source("azure:first")


def test_open3d_mkv_reader_needs_libk4arecord():
    """The reason mkv: uses PyAV (stated in swarmpose.sources.mkv): Open3D's reader needs libk4arecord.so."""
    mkv = ASSETS / "rgbd" / "azure_kinect_one_frame" / "recording.mkv"
    if _k4a_loads() or not mkv.is_file():
        pytest.skip("the Azure Kinect SDK is installed, or the recording is absent")
    with pytest.raises(RuntimeError, match=r"Cannot load \S*libk4arecord\.so: cannot open shared object file"):
        o3d.io.AzureKinectMKVReader().open(str(mkv))
