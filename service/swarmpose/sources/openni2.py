"""``openni2:``: OpenNI2 devices (PrimeSense, Kinect v1 through drivers, Orbbec, Asus Xtion) and
``.oni`` recordings, through the ``openni`` Python bindings (``from openni import openni2``).

* ``openni2:`` opens the first device OpenNI2 enumerates; ``openni2:URI`` a device by its
  OpenNI URI (``Dummy`` is the test device of Debian's DummyDevice driver);
  ``openni2:FILE.oni`` plays a recording, every frame in order (manual playback speed, no
  repeat), and ends after its last frame.
* The native library: Debian's ``libopenni2-0`` (``libOpenNI2.so.0`` and the drivers in
  ``<libdir>/OpenNI2/Drivers``: PS1080, PSLink, OniFile, DummyDevice) and ``libopenni2-dev``
  (the ``libOpenNI2.so`` name the bindings load). :func:`locate_openni2` finds the directory
  holding ``libOpenNI2.so`` (``$OPENNI2_REDIST64``/``$OPENNI2_REDIST``, ``ldconfig``'s cache,
  the usual library directories); OpenNI2 itself finds the drivers relative to the library
  (``OpenNI2/Drivers``, the default of ``/etc/openni2/OpenNI.ini``).
* Frames: depth ``DEPTH_1_MM`` or ``DEPTH_100_UM`` converted to metres; depth registered to
  colour by the device when it supports ``IMAGE_REGISTRATION_DEPTH_TO_COLOR`` (then the
  intrinsics are the colour camera's); otherwise ``registered`` is False and colour, when it
  has the depth image's size, is delivered as the device gives it. Intrinsics from the
  stream's field of view (fx = W / 2 / tan(hfov / 2), principal point at the image centre);
  when the stream reports none (recordings of devices without the property), the Kinect v1's
  f = 525 px at 640x480, scaled to the image width (``intrinsics_nominal`` is then True).
  Timestamps: the frames' µs clock (device, or the recording's, starting at 0), as ns.
* Live failures (a read times out, the device is unplugged) follow the policy of
  :mod:`.base`: skipped frames and at most ``MAX_RECONNECTS`` reopenings.

Two defects of Debian's OpenNI2 2.2.0.33 concern only its test device: a process that opened
``Dummy`` dies with a segmentation fault when it exits (inside OpenNI2's shutdown, after all
frames were delivered), and the OniFile player drops every frame of a recording made from
``Dummy``, whose streams lack the cropping property the player reads for each frame
(recordings of real devices carry it). The tests therefore use ``Dummy`` in a child process
and add the missing property record to its recordings.
"""

from __future__ import annotations

import math
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SourceError
from swarmpose.sources.base import Frame, FrameSource, SkippedFrame, exc_message, live_frames

APT_PACKAGES = ("libopenni2-0", "libopenni2-dev")
LIBRARY = "libOpenNI2.so"
READ_TIMEOUT_S = 2.0
FILE_READ_ATTEMPTS = 3
KINECT_V1_FOCAL_640 = 525.0
_INSTALL = f"install OpenNI2: `sudo apt-get install {' '.join(APT_PACKAGES)}` (Debian/Ubuntu)"


def _candidate_dirs() -> list[Path]:
    dirs = [Path(os.environ[v]) for v in ("OPENNI2_REDIST64", "OPENNI2_REDIST") if os.environ.get(v)]
    for ldconfig in ("ldconfig", "/sbin/ldconfig"):
        try:
            out = subprocess.run([ldconfig, "-p"], capture_output=True, text=True, timeout=10).stdout
        except (OSError, subprocess.SubprocessError):
            continue
        for line in out.splitlines():
            if "libOpenNI2.so" in line and "=>" in line:
                dirs.append(Path(line.split("=>")[1].strip()).parent)
        break
    dirs += [Path(p) for p in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib",
                               "/usr/local/lib", "/lib", "/lib64")]
    unique = []
    for d in dirs:
        if d not in unique:
            unique.append(d)
    return unique


def locate_openni2(search: list[Path] | None = None) -> Path:
    """The directory holding ``libOpenNI2.so`` with an ``OpenNI2/Drivers`` folder beside it.

    ``search``: directories to try (default: the environment, ldconfig and the usual places).
    SourceError naming the apt packages when none qualifies.
    """
    runtime_only = None
    for d in search if search is not None else _candidate_dirs():
        if (d / LIBRARY).is_file():
            if not (d / "OpenNI2" / "Drivers").is_dir():
                raise SourceError(f"openni2: {d / LIBRARY} has no driver folder {d / 'OpenNI2' / 'Drivers'}; "
                                  f"{_INSTALL}")
            return d
        if (d / (LIBRARY + ".0")).is_file():
            runtime_only = d
    if runtime_only is not None:
        raise SourceError(f"openni2: {runtime_only / (LIBRARY + '.0')} exists but not {LIBRARY}, the name the "
                          f"Python bindings load; {_INSTALL}")
    raise SourceError(f"openni2: the OpenNI2 library ({LIBRARY}) is not installed; {_INSTALL}")


_openni2 = None


def openni2_module():
    """``openni.openni2``, initialised once from :func:`locate_openni2`'s directory."""
    global _openni2
    if _openni2 is not None:
        return _openni2
    try:
        from openni import openni2
    except ImportError as exc:  # pragma: no cover - openni is a dependency
        raise SourceError("openni2: needs the Python bindings (`pip install openni`)") from exc
    if not openni2.is_initialized():
        directory = locate_openni2()
        try:
            openni2.initialize(str(directory))
        except Exception as exc:  # openni raises its own InitializationError, or OSError from ctypes
            raise SourceError(f"openni2: cannot initialise {directory / LIBRARY} ({exc_message(exc)}); "
                              f"{_INSTALL}") from exc
    _openni2 = openni2
    return openni2


def fov_intrinsics(width: int, height: int, hfov: float | None, vfov: float | None) -> tuple[Intrinsics, bool]:
    """Pinhole intrinsics from fields of view (radians); (intrinsics, nominal) where nominal means
    the fields of view were unknown and the Kinect v1's f = 525 px at 640 px wide was used."""
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    if hfov and vfov and 0 < hfov < math.pi and 0 < vfov < math.pi:
        return Intrinsics(width, height, width / 2 / math.tan(hfov / 2), height / 2 / math.tan(vfov / 2), cx, cy), False
    f = KINECT_V1_FOCAL_640 * width / 640.0
    return Intrinsics(width, height, f, f, cx, cy), True


def _depth_array(frame, units_per_metre: float) -> np.ndarray:
    h, w = frame.height, frame.width
    stride = frame.stride // 2 if frame.stride else w
    raw = np.frombuffer(frame.get_buffer_as_uint16(), dtype=np.uint16, count=h * stride).reshape(h, stride)[:, :w]
    return (raw.astype(np.float32) / np.float32(units_per_metre)).astype(np.float32)


def _color_array(frame, openni2) -> np.ndarray | None:
    import cv2

    h, w = frame.height, frame.width
    fmt = frame.videoMode.pixelFormat
    data = np.frombuffer(frame.get_buffer_as_uint8(), dtype=np.uint8)
    if fmt == openni2.PIXEL_FORMAT_RGB888:
        stride = frame.stride or w * 3
        return data[: h * stride].reshape(h, stride)[:, : w * 3].reshape(h, w, 3).copy()
    if fmt == openni2.PIXEL_FORMAT_GRAY8:
        stride = frame.stride or w
        return np.repeat(data[: h * stride].reshape(h, stride)[:, :w, None], 3, axis=2)
    if fmt in (openni2.PIXEL_FORMAT_YUV422, openni2.PIXEL_FORMAT_YUYV):
        code = cv2.COLOR_YUV2RGB_UYVY if fmt == openni2.PIXEL_FORMAT_YUV422 else cv2.COLOR_YUV2RGB_YUYV
        return cv2.cvtColor(data[: h * w * 2].reshape(h, w, 2), code)
    if fmt == openni2.PIXEL_FORMAT_JPEG:
        img = cv2.imdecode(data[: frame.dataSize], cv2.IMREAD_COLOR)
        return None if img is None else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return None


class OpenNI2Source(FrameSource):
    """An OpenNI2 device or ``.oni`` recording (see the module docstring).

    Attributes: ``file`` (Path or None), ``device_uri``, ``registered`` (depth registered to
    colour by the device), ``intrinsics``, ``intrinsics_nominal``, ``fps``, ``length``
    (frames of a recording, None live), ``read_timeout_s`` (how long one read waits; a
    recording is read again up to ``FILE_READ_ATTEMPTS`` times before it counts as ended).
    """

    def __init__(self, file: Path | str | None = None, device_uri: str | None = None, uri: str | None = None):
        self.file = Path(file) if file is not None else None
        self.device_uri = device_uri
        self.read_timeout_s = READ_TIMEOUT_S
        self.uri = uri or (f"openni2:{self.file}" if self.file else f"openni2:{device_uri or ''}")
        self._device = self._depth = self._color = None
        self._openni2 = openni2_module()
        try:
            self._open()
        except Exception:
            self.close()
            raise

    # -- opening -----------------------------------------------------------------------------

    def _open_device(self):
        openni2 = self._openni2
        try:
            if self.file is not None:
                return openni2.Device.open_file(str(self.file).encode())
            uri = self.device_uri
            if not uri:
                uris = [u for u in openni2.Device.enumerate_uris()  # open recordings are listed too
                        if not (u.decode() if isinstance(u, bytes) else str(u)).lower().endswith(".oni")]
                if not uris:
                    raise SourceError("openni2: no OpenNI2 device is connected (checked the drivers in "
                                      f"{openni2.loaded_dll_directory}/OpenNI2/Drivers); plug one in or play a "
                                      "recording with openni2:FILE.oni")
                uri = uris[0].decode() if isinstance(uris[0], bytes) else str(uris[0])
            return openni2.Device(uri.encode())
        except SourceError:
            raise
        except Exception as exc:  # openni raises OpenNIError
            what = self.file or self.device_uri or "the first device"
            raise SourceError(f"openni2: cannot open {what} ({exc_message(exc)})") from exc

    def _open(self) -> None:
        openni2 = self._openni2
        self._device = dev = self._open_device()
        try:
            if not dev.has_sensor(openni2.SENSOR_DEPTH):
                raise SourceError(f"openni2: {self.file or self.device_uri or 'the device'} has no depth stream")
            self._depth = dev.create_depth_stream()
            self._color = dev.create_color_stream() if dev.has_sensor(openni2.SENSOR_COLOR) else None
            mode = self._depth.get_video_mode()
            if mode.pixelFormat == openni2.PIXEL_FORMAT_DEPTH_1_MM:
                self._units = 1000.0
            elif mode.pixelFormat == openni2.PIXEL_FORMAT_DEPTH_100_UM:
                self._units = 10000.0
            else:
                raise SourceError(f"openni2: depth pixel format {mode.pixelFormat} is not metric "
                                  "(expected DEPTH_1_MM or DEPTH_100_UM)")
            self.fps = float(mode.fps) if mode.fps else 30.0
            self.registered = False
            if self._color is not None and dev.is_image_registration_mode_supported(
                    openni2.IMAGE_REGISTRATION_DEPTH_TO_COLOR):
                dev.set_image_registration_mode(openni2.IMAGE_REGISTRATION_DEPTH_TO_COLOR)
                self.registered = True
            if self.file is not None:
                dev.playback.set_repeat_enabled(False)
                dev.playback.set_speed(-1.0)  # manual: one recorded frame per read, none dropped
                self.length = int(dev.playback.get_number_of_frames(self._depth)) or None
                self._colors_left = (int(dev.playback.get_number_of_frames(self._color))
                                     if self._color is not None else 0)
            else:
                self.length, self.live = None, True
                if self._color is not None:
                    try:
                        dev.set_depth_color_sync_enabled(True)
                    except Exception:  # optional on devices that lack it
                        pass
            self._depth.start()
            if self._color is not None:
                self._color.start()
        except SourceError:
            raise
        except Exception as exc:
            raise SourceError(f"openni2: cannot start the streams of {self.file or self.device_uri or 'the device'} "
                              f"({exc_message(exc)})") from exc
        ref = self._color if (self.registered and self._color is not None) else self._depth
        mode = ref.get_video_mode()
        try:
            hfov, vfov = ref.get_horizontal_fov(), ref.get_vertical_fov()
        except Exception:  # the property is optional (recordings of devices without it)
            hfov = vfov = None
        self.intrinsics, self.intrinsics_nominal = fov_intrinsics(mode.resolutionX, mode.resolutionY, hfov, vfov)

    # -- frames ------------------------------------------------------------------------------

    def _read(self, stream):
        """The next frame of ``stream`` or None after ``read_timeout_s``."""
        if self._openni2.wait_for_any_stream([stream], timeout=self.read_timeout_s) is None:
            return None
        return stream.read_frame()

    def _next(self, index: int, pending: list) -> Frame | SkippedFrame | None:
        """One depth frame paired with the colour frame of the same time (``pending`` keeps an early colour)."""
        depth_frame = self._read(self._depth)
        if depth_frame is None:
            return None
        t_ns = int(depth_frame.timestamp) * 1000
        depth = _depth_array(depth_frame, self._units)
        if depth.shape != (self.intrinsics.height, self.intrinsics.width) and self.registered:
            return SkippedFrame(index, t_ns, f"{self.uri}: depth {depth.shape[1]}x{depth.shape[0]} does not match "
                                             f"the registered colour {self.intrinsics.width}x{self.intrinsics.height}")
        color = None
        if self._color is not None:
            half = 0.5e9 / self.fps
            while not pending or pending[0][0] < t_ns - half:
                if self.file is not None and self._colors_left <= 0:
                    break  # the recording's colour stream has ended
                color_frame = self._read(self._color)
                if color_frame is None:
                    break
                if self.file is not None:
                    self._colors_left -= 1
                pending[:] = [(int(color_frame.timestamp) * 1000, _color_array(color_frame, self._openni2))]
            if pending and abs(pending[0][0] - t_ns) <= half:
                color = pending.pop()[1]
            if color is not None and color.shape[:2] != depth.shape:
                color = None  # unregistered colour of another size: not usable with this depth
        if depth.shape != (self.intrinsics.height, self.intrinsics.width):
            self.intrinsics, self.intrinsics_nominal = fov_intrinsics(depth.shape[1], depth.shape[0], None, None)
        return Frame(index, t_ns, depth, color, self.intrinsics)

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        pending: list = []
        if self.file is not None:
            index = 0
            while self.length is None or index < self.length:
                item = None
                for _ in range(FILE_READ_ATTEMPTS):  # a busy machine can delay the player thread
                    try:
                        item = self._next(index, pending)
                    except Exception as exc:
                        raise SourceError(f"{self.uri}: reading frame {index} failed ({exc_message(exc)})") from exc
                    if item is not None or self.length is None:
                        break
                if item is None:
                    if index == 0:
                        raise SourceError(f"{self.uri}: the recording delivers no frames (OpenNI2's player "
                                          "dropped them, or the file is empty)")
                    if self.length is not None:
                        self.status = f"error: {self.uri}: the recording ended after {index} of {self.length} frames"
                    return
                yield item
                index += 1
            return

        def capture(index: int) -> Frame | SkippedFrame | None:
            try:
                return self._next(index, pending)
            except Exception as exc:
                raise SourceError(exc_message(exc)) from exc

        yield from live_frames(self.uri, capture, self._reopen)

    def _reopen(self) -> None:
        self.close()
        self._open()

    def close(self) -> None:
        for stream in (self._color, self._depth):
            if stream is not None:
                try:
                    stream.stop()
                    stream.close()
                except Exception:  # closing twice or after the device vanished
                    pass
        if self._device is not None:
            try:
                self._device.close()
            except Exception:  # the device may be gone already
                pass
        self._device = self._depth = self._color = None
