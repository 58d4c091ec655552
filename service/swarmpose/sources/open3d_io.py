"""Sources read through Open3D: ``bag:`` (RealSense recordings), ``realsense:`` and ``azure:`` (live).

* ``bag:FILE.bag`` — ``open3d.t.io.RGBDVideoReader.create`` (an ``RSBagReader``; depth aligned to
  colour by librealsense), intrinsics and depth scale from the reader's metadata,
  timestamps from ``get_timestamp()`` (µs in the recording).
* ``realsense:[SERIAL|CONFIG.json]`` — ``open3d.t.io.RealSenseSensor``: the first camera, the one
  with that serial number, or an Open3D ``RealSenseSensorConfig`` JSON (string values, e.g.
  ``{"serial": "…", "color_resolution": "1280,720", "depth_resolution": "1280,720", "fps": "30"}``);
  frames captured with ``align_depth_to_color=True``, timestamps from ``get_timestamp()`` (µs,
  device clock).
* ``azure:[INDEX][,INTRINSICS.json]`` — ``open3d.io.AzureKinectSensor`` with Open3D's default
  configuration, ``capture_frame(True)`` (depth aligned to colour by the Azure Kinect SDK).
  Open3D's live sensor does not expose the calibration, so the colour intrinsics come from
  INTRINSICS.json when given, else from the factory calibration that a one-frame
  ``AzureKinectRecorder`` recording attaches (parsed by :mod:`.k4a_calibration`).
  Timestamps are the host's monotonic clock at capture (Open3D's legacy RGBD image carries
  none).

Both live readers need their vendor library at run time (librealsense is inside Open3D's
wheel; the Azure Kinect SDK's ``libk4a.so`` is not, and Debian has no package for it); when
it, or the device, is missing the source raises :class:`~swarmpose.core.errors.SourceError`
saying so. Live capture failures after the first frame follow the policy of
:mod:`.base`: each failed capture is a :class:`~.base.SkippedFrame`, then the device is
reopened, at most :data:`~.base.MAX_RECONNECTS` times in a row, before the source ends with
``status`` = ``"error: …"``.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.core.open3d_import import open3d
from swarmpose.sources.base import CAPTURE_RETRIES, Frame, FrameSource, SkippedFrame, exc_message, live_frames
from swarmpose.sources.imagefiles import MILLIMETRES, check_pair, depth_to_metres, load_intrinsics


def intrinsics_from_open3d(intrinsic) -> Intrinsics:
    """``open3d.camera.PinholeCameraIntrinsic`` -> :class:`~swarmpose.core.camera.Intrinsics`."""
    k = np.asarray(intrinsic.intrinsic_matrix, dtype=np.float64)
    return Intrinsics(int(intrinsic.width), int(intrinsic.height), float(k[0, 0]), float(k[1, 1]),
                      float(k[0, 2]), float(k[1, 2]))


def _pixels(image) -> np.ndarray:
    """The pixels of an Open3D image, legacy (``open3d.geometry.Image``) or tensor (``open3d.t.geometry.Image``)."""
    if hasattr(image, "as_tensor"):
        return image.as_tensor().cpu().numpy()
    return np.asarray(image)


def rgbd_to_frame(rgbd, intrinsics: Intrinsics, depth_scale: float, index: int, timestamp_ns: int) -> Frame:
    """An Open3D RGBD image (legacy ``open3d.geometry.RGBDImage`` or ``open3d.t.geometry.RGBDImage``)
    -> :class:`~.base.Frame`.

    Depth: integer images are sensor units (``depth_scale`` units per metre, e.g. 1000 for
    millimetres); float images are already metres (Open3D's convention after
    ``create_from_color_and_depth``). Colour: uint8 RGB with 3 channels (a 4th, alpha, is
    dropped; single-channel intensity is repeated) or float 0..1 (scaled to 0..255).
    Raises SourceError when depth and colour, or depth and ``intrinsics``, differ in size.
    """
    depth = _pixels(rgbd.depth)
    if depth.ndim == 3:
        depth = depth[:, :, 0]
    if np.issubdtype(depth.dtype, np.floating):
        depth_m = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
    else:
        depth_m = depth_to_metres(depth, depth_scale)
    color = _pixels(rgbd.color)
    if color.size == 0:
        color = None
    else:
        if np.issubdtype(color.dtype, np.floating):
            color = np.clip(np.rint(color * 255.0), 0, 255).astype(np.uint8)
        color = np.ascontiguousarray(color, dtype=np.uint8)
        if color.ndim == 2:
            color = np.repeat(color[:, :, None], 3, axis=2)
        elif color.shape[2] == 1:
            color = np.repeat(color, 3, axis=2)
        elif color.shape[2] == 4:
            color = np.ascontiguousarray(color[:, :, :3])
    mismatch = check_pair(depth_m, color, f"frame {index}", intrinsics)
    if mismatch:
        raise SourceError(mismatch)
    return Frame(index, int(timestamp_ns), depth_m, color, intrinsics)


def _open3d():
    o3d = open3d()
    return o3d


class BagSource(FrameSource):
    """A RealSense ``.bag`` recording through Open3D's ``RSBagReader``.

    Attributes: ``path``, ``fps``, ``length`` (from the recording's duration), ``intrinsics``,
    ``depth_scale`` (units per metre), ``metadata`` (Open3D's ``RGBDVideoMetadata``).
    """

    def __init__(self, path: Path | str, uri: str | None = None):
        o3d = _open3d()
        self.path = Path(path)
        self.uri = uri or f"bag:{self.path}"
        try:
            self._reader = o3d.t.io.RGBDVideoReader.create(str(self.path))
        except RuntimeError as exc:
            raise SourceError(f"bag: Open3D cannot read {self.path} ({exc_message(exc)})") from exc
        if not self._reader.is_opened():
            raise SourceError(f"bag: {self.path} is not a readable RealSense recording (Open3D's RSBagReader "
                              "could not open it); record one with the RealSense Viewer (realsense-viewer)")
        meta = self.metadata = self._reader.metadata
        self.intrinsics = intrinsics_from_open3d(meta.intrinsics)
        self.depth_scale = float(meta.depth_scale) if meta.depth_scale > 0 else MILLIMETRES
        self.fps = float(meta.fps) if meta.fps > 0 else 30.0
        self.length = int(round(meta.stream_length_usec * 1e-6 * self.fps)) or None

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        index = 0
        while not self._reader.is_eof():
            rgbd = self._reader.next_frame()
            t_ns = int(self._reader.get_timestamp()) * 1000
            if rgbd.is_empty():
                if self._reader.is_eof():
                    break
                yield SkippedFrame(index, t_ns, f"{self.path.name}: empty frame at {t_ns} ns")
            else:
                try:
                    yield rgbd_to_frame(rgbd, self.intrinsics, self.depth_scale, index, t_ns)
                except SourceError as exc:
                    yield SkippedFrame(index, t_ns, f"{self.path.name}: {exc}")
            index += 1

    def close(self) -> None:
        reader = getattr(self, "_reader", None)
        if reader is not None:
            reader.close()
            self._reader = None


class _LiveSensorSource(FrameSource):
    """A live Open3D sensor: subclasses open it (``_open``), capture one frame (``_capture``,
    None when none came) and close it; reconnecting follows :func:`live_frames`."""

    live = True

    def _open(self) -> None:
        raise NotImplementedError

    def _capture(self, index: int) -> Frame | None:
        raise NotImplementedError

    def _reopen(self) -> None:
        self.close()
        self._open()

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        yield from live_frames(self.uri, self._capture, self._reopen)


class RealSenseSource(_LiveSensorSource):
    """A live RealSense camera through ``open3d.t.io.RealSenseSensor`` (see the module docstring)."""

    def __init__(self, spec: str = "", uri: str | None = None):
        o3d = _open3d()
        self.uri = uri or f"realsense:{spec}"
        self.length = None
        self._config = self._parse(spec)
        try:
            devices = o3d.t.io.RealSenseSensor.enumerate_devices()
        except RuntimeError as exc:
            raise SourceError(f"realsense: librealsense (inside Open3D) cannot list cameras ({exc_message(exc)})"
                              ) from exc
        if not devices:
            raise SourceError("realsense: no RealSense camera is connected; plug one in (USB 3) or read a "
                              "recording with bag:FILE.bag")
        self._sensor = None
        self._open()

    @staticmethod
    def _parse(spec: str) -> dict:
        spec = spec.strip()
        if not spec:
            return {}
        if spec.lower().endswith(".json"):
            path = Path(spec).expanduser()
            try:
                config = json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                raise SourceError(f"realsense: cannot read the configuration {path} ({exc})") from exc
            if not isinstance(config, dict):
                raise ConfigError(f"realsense: {path} must hold a JSON object of Open3D RealSenseSensorConfig keys")
            return {str(k): str(v) for k, v in config.items()}
        return {"serial": spec}

    def _open(self) -> None:
        o3d = _open3d()
        sensor = o3d.t.io.RealSenseSensor()
        try:
            if not sensor.init_sensor(o3d.t.io.RealSenseSensorConfig(self._config), 0):
                raise RuntimeError("init_sensor refused the configuration")
            sensor.start_capture(False)
        except RuntimeError as exc:
            raise SourceError(f"realsense: cannot start the camera {self._config or ''}({exc_message(exc)})"
                              ) from exc
        meta = sensor.get_metadata()
        self._sensor = sensor
        self.intrinsics = intrinsics_from_open3d(meta.intrinsics)
        self.depth_scale = float(meta.depth_scale) if meta.depth_scale > 0 else MILLIMETRES
        self.fps = float(meta.fps) if meta.fps > 0 else 30.0

    def _capture(self, index: int) -> Frame | None:
        rgbd = self._sensor.capture_frame(True, True)
        if rgbd.is_empty():
            return None
        return rgbd_to_frame(rgbd, self.intrinsics, self.depth_scale, index, int(self._sensor.get_timestamp()) * 1000)

    def close(self) -> None:
        sensor = getattr(self, "_sensor", None)
        if sensor is not None:
            try:
                sensor.stop_capture()
            except RuntimeError:
                pass
            self._sensor = None


def _azure_sdk_error(exc: Exception) -> SourceError:
    return SourceError(f"azure: Open3D cannot use the Azure Kinect SDK ({exc_message(exc)}); install Microsoft's "
                       "Azure Kinect Sensor SDK (libk4a, libk4arecord; Debian has no package), or read a "
                       "recording with mkv:FILE.mkv")


class AzureKinectSource(_LiveSensorSource):
    """A live Azure Kinect through ``open3d.io.AzureKinectSensor`` (see the module docstring)."""

    def __init__(self, spec: str = "", uri: str | None = None):
        o3d = _open3d()
        self.uri = uri or f"azure:{spec}"
        self.length = None
        parts = [p.strip() for p in spec.split(",")] if spec.strip() else []
        try:
            self.device_index = int(parts[0]) if parts and parts[0] else 0
        except ValueError as exc:
            raise ConfigError(f"azure: the device index must be an integer, got {parts[0]!r}") from exc
        if len(parts) > 2:
            raise ConfigError(f"azure: expected azure:[INDEX][,INTRINSICS.json], got {spec!r}")
        self._given = load_intrinsics(Path(parts[1]).expanduser())[0] if len(parts) == 2 and parts[1] else None
        try:
            o3d.io.AzureKinectSensor.list_devices()
        except RuntimeError as exc:
            raise _azure_sdk_error(exc) from exc
        self._calibration = None if self._given is not None else self._factory_calibration()
        self._sensor = None
        self._open()
        self.intrinsics: Intrinsics | None = self._given
        self.fps = 30.0

    def _factory_calibration(self) -> dict:
        """The device's calibration.json, from a one-frame recording made with Open3D's AzureKinectRecorder."""
        o3d = _open3d()
        from swarmpose.sources.mkv import MkvSource

        with tempfile.TemporaryDirectory(prefix="swarmpose-k4a-") as tmp:
            path = Path(tmp) / "calibration.mkv"
            try:
                recorder = o3d.io.AzureKinectRecorder(o3d.io.AzureKinectSensorConfig(), self.device_index)
                if not recorder.init_sensor() or not recorder.open_record(str(path)):
                    raise SourceError(f"azure: no Azure Kinect at index {self.device_index} (or it is busy)")
                for _ in range(CAPTURE_RETRIES):
                    recorder.record_frame(True, False)
                recorder.close_record()
            except RuntimeError as exc:
                raise _azure_sdk_error(exc) from exc
            source = MkvSource(path)
            try:
                return source.calibration
            finally:
                source.close()

    def _open(self) -> None:
        o3d = _open3d()
        sensor = o3d.io.AzureKinectSensor(o3d.io.AzureKinectSensorConfig())
        try:
            ok = sensor.connect(self.device_index)
        except RuntimeError as exc:
            raise _azure_sdk_error(exc) from exc
        if not ok:
            raise SourceError(f"azure: cannot connect to the Azure Kinect at index {self.device_index}; is it "
                              "plugged in (USB 3 and power) and not used by another program?")
        self._sensor = sensor

    def _capture(self, index: int) -> Frame | None:
        rgbd = self._sensor.capture_frame(True)
        t_ns = time.monotonic_ns()
        if rgbd is None:
            return None
        if self.intrinsics is None:
            from swarmpose.sources.k4a_calibration import color_model
            height = _pixels(rgbd.color).shape[0]
            self.intrinsics = color_model(self._calibration, height).pinhole
        return rgbd_to_frame(rgbd, self.intrinsics, MILLIMETRES, index, t_ns)

    def close(self) -> None:
        sensor = getattr(self, "_sensor", None)
        if sensor is not None:
            try:
                sensor.disconnect()
            except RuntimeError:
                pass
            self._sensor = None
