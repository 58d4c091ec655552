"""``mkv:FILE.mkv``: Azure Kinect recordings (k4arecorder's Matroska files), read with PyAV.

Why not Open3D: ``open3d.io.AzureKinectMKVReader`` loads the Azure Kinect SDK's
``libk4arecord.so`` at run time and Debian ships no package with it, so on this platform
``AzureKinectMKVReader().open(path)`` raises ``RuntimeError: [Open3D Error] (…K4aPlugin.cpp:150)
Cannot load libk4arecord.so: cannot open shared object file: No such file or directory``
(checked with Open3D 0.20 on Debian 12; the name may carry the directory Open3D tried). The
recording is plain Matroska, so PyAV (FFmpeg) demuxes it instead.

The file: track ``COLOR`` (MJPEG, or raw BGRA/NV12/YUY2), track ``DEPTH`` (16-bit grey, codec
tag ``b16g``, millimetres; FFmpeg decodes it as big-endian ``gray16be``, which gives the
right values), track ``IR``, an IMU subtitle track, and the attachment ``calibration.json``
(the factory calibration, :mod:`.k4a_calibration`). Block timestamps are µs from the
recording start; ``K4A_START_OFFSET_NS`` (file tag) is added to give the device time.

Frames in swarmpose's conventions: depth in metres *registered to colour*: every depth pixel
is reprojected into the colour camera with both lenses' Brown-Conrady distortion and the
depth→colour extrinsics, z-buffered (:class:`~.registration.DepthRegistration`), so depth
and colour have the colour image's size; ``intrinsics`` are the colour camera's pinhole
part (its lens distortion is small and is not removed from the colour image). A recording
without a colour track yields depth reprojected onto an undistorted pinhole image of the
depth camera, with ``color`` None.

Colour and depth of one capture are paired by timestamp (within half a frame period, after
``K4A_DEPTH_DELAY_NS``); a capture missing one of them, or a packet that fails to decode,
is yielded as a :class:`~.base.SkippedFrame`. A file truncated mid-stream ends the
iteration (``status`` says why) after the frames before the damage.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from swarmpose.core.errors import SourceError
from swarmpose.sources.base import Frame, FrameSource, SkippedFrame, exc_message
from swarmpose.sources.k4a_calibration import color_model, depth_mode_for_size, depth_model
from swarmpose.sources.registration import DepthRegistration

DEFAULT_FPS = 30.0


def _import_av():
    try:
        import av
    except ImportError as exc:  # pragma: no cover - av is a dependency
        raise SourceError("mkv: needs PyAV (`pip install av`)") from exc
    return av


class MkvSource(FrameSource):
    """Frames of an Azure Kinect MKV recording (see the module docstring).

    Attributes: ``path``, ``fps`` (from ``K4A_COLOR_MODE``/the stream rate, default 30),
    ``length`` (depth frames when the container states it, else None), ``intrinsics``
    (colour pinhole), ``depth_camera`` / ``color_camera`` (:class:`~.k4a_calibration.CameraModel`),
    ``calibration`` (the parsed calibration.json).
    """

    def __init__(self, path: Path | str, uri: str | None = None):
        av = _import_av()
        self.path = Path(path)
        self.uri = uri or f"mkv:{self.path}"
        try:
            self._container = av.open(str(self.path))
        except (av.error.FFmpegError, OSError, ValueError) as exc:
            raise SourceError(f"mkv: cannot open {self.path} ({exc_message(exc)}); is it a Matroska "
                              "recording of an Azure Kinect?") from exc
        try:
            self._setup()
        except Exception:
            self.close()
            raise

    def _setup(self) -> None:
        c = self._container
        video = list(c.streams.video)
        titled = {(s.metadata.get("title") or "").upper(): s for s in video}
        self._depth = titled.get("DEPTH") or next(
            (s for s in video if (s.codec_context.pix_fmt or "").startswith("gray16") and s is not titled.get("IR")),
            None)
        if self._depth is None:
            raise SourceError(f"mkv: {self.path} has no DEPTH track (16-bit depth video); "
                              "record with the depth camera on")
        self._color = titled.get("COLOR") or next(
            (s for s in video if s is not self._depth and s is not titled.get("IR")
             and not (s.codec_context.pix_fmt or "").startswith("gray16")), None)
        self.calibration = self._read_calibration()
        dw, dh = self._depth.codec_context.width, self._depth.codec_context.height
        mode = (self._depth.metadata.get("K4A_DEPTH_MODE") or "").upper() or depth_mode_for_size(dw, dh)
        self.depth_camera = depth_model(self.calibration, mode)
        if (self.depth_camera.width, self.depth_camera.height) != (dw, dh):
            raise SourceError(f"mkv: depth track is {dw}x{dh} but depth mode {mode} is "
                              f"{self.depth_camera.width}x{self.depth_camera.height}")
        if self._color is not None:
            self.color_camera = color_model(self.calibration, self._color.codec_context.height)
        else:  # depth only: an undistorted pinhole image of the depth camera
            self.color_camera = replace(self.depth_camera, dist=np.zeros(8))
        self.intrinsics = self.color_camera.pinhole
        self._registration = DepthRegistration(self.depth_camera, self.color_camera)
        tags = {k.upper(): v for k, v in c.metadata.items()}
        self._start_ns = int(tags.get("K4A_START_OFFSET_NS", 0) or 0)
        self._depth_delay_ns = int(tags.get("K4A_DEPTH_DELAY_NS", 0) or 0)
        rate = self._depth.average_rate or self._depth.guessed_rate
        fps = float(rate) if rate else 0.0
        self.fps = fps if 0 < fps <= 120 else DEFAULT_FPS
        self.length = int(self._depth.frames) or None

    def _read_calibration(self) -> dict:
        for s in self._container.streams:
            if s.type == "attachment" and (s.metadata.get("filename") or "").lower() == "calibration.json":
                try:
                    return json.loads(bytes(s.data))
                except ValueError as exc:
                    raise SourceError(f"mkv: {self.path}: attached calibration.json is not JSON ({exc})") from exc
        beside = self.path.with_name("calibration.json")
        if beside.is_file():
            try:
                return json.loads(beside.read_text())
            except (OSError, ValueError) as exc:
                raise SourceError(f"mkv: {beside} is not readable JSON ({exc})") from exc
        raise SourceError(f"mkv: {self.path} has no calibration.json attachment and none lies beside it; "
                          "swarmpose needs the factory calibration to register depth to colour")

    @property
    def depth_to_color(self) -> tuple[np.ndarray, np.ndarray]:
        """(R (3, 3), t (3,) m): x_colour = R x_depth + t."""
        return self._registration.R, self._registration.t

    def register(self, depth_m: np.ndarray, values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Depth (H_d, W_d) metres of the depth camera -> (H_c, W_c) metres registered to colour
        (and ``values``, e.g. the IR image, carried along; see :class:`~.registration.DepthRegistration`)."""
        return self._registration(depth_m, values)

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        av = _import_av()
        streams = [s for s in (self._color, self._depth) if s is not None]
        period_ns = 1e9 / self.fps
        pending: dict[str, tuple[int, int, np.ndarray]] = {}  # kind -> (pairing time, device time, pixels)
        index = 0

        def ts_of(frame, stream) -> int:
            pts = frame.pts if frame.pts is not None else 0
            return int(round(float(pts * stream.time_base) * 1e9)) + self._start_ns

        def complete() -> Frame | None:
            nonlocal index
            if "depth" not in pending or (self._color is not None and "color" not in pending):
                return None
            _, t_depth, raw = pending.pop("depth")
            color = None
            if self._color is not None:
                color = pending.pop("color")[2]
            registered, _ = self._registration(raw.astype(np.float32) / np.float32(1000.0))
            frame = Frame(index, t_depth, registered, color, self.intrinsics)
            index += 1
            return frame

        def stale(kind: str, t_new: int) -> SkippedFrame | None:
            """The pending frame of the other kind is too old to pair with one at t_new."""
            nonlocal index
            other = "color" if kind == "depth" else "depth"
            if other in pending and t_new - pending[other][0] > period_ns / 2:
                _, t_old, _ = pending.pop(other)
                name = "COLOR" if other == "depth" else "DEPTH"
                skipped = SkippedFrame(index, t_old, f"{self.path.name}: no {name} frame for the "
                                                     f"{other.upper()} frame at {t_old} ns")
                index += 1
                return skipped
            return None

        packets = self._container.demux(*streams)
        while True:
            try:
                packet = next(packets)
            except StopIteration:
                break
            except av.error.FFmpegError as exc:
                raise SourceError(f"mkv: {self.path} is damaged after frame {index} ({exc_message(exc)})") from exc
            if packet.size == 0:
                continue
            stream = packet.stream
            kind = "depth" if stream is self._depth else "color"
            try:
                decoded = packet.decode()
                arrays = [(ts_of(f, stream), f.to_ndarray() if kind == "depth" else f.to_ndarray(format="rgb24"))
                          for f in decoded]
            except (av.error.FFmpegError, ValueError) as exc:
                t = int(round(float((packet.pts or 0) * stream.time_base) * 1e9)) + self._start_ns
                yield SkippedFrame(index, t, f"{self.path.name}: {kind} packet at {t} ns cannot be decoded "
                                             f"({exc_message(exc)})")
                index += 1
                continue
            for t, array in arrays:
                if kind == "depth" and (array.dtype != np.uint16 or array.shape != (self.depth_camera.height,
                                                                                     self.depth_camera.width)):
                    yield SkippedFrame(index, t, f"{self.path.name}: depth frame at {t} ns is {array.dtype} "
                                                 f"{array.shape}, expected uint16 "
                                                 f"{(self.depth_camera.height, self.depth_camera.width)}")
                    index += 1
                    continue
                key = t - self._depth_delay_ns if kind == "depth" else t
                old = stale(kind, key)
                if old is not None:
                    yield old
                if kind in pending:  # a second frame of one kind before its partner: drop the older
                    t_old = pending[kind][1]
                    yield SkippedFrame(index, t_old, f"{self.path.name}: no "
                                                     f"{'COLOR' if kind == 'depth' else 'DEPTH'} frame for the "
                                                     f"{kind.upper()} frame at {t_old} ns")
                    index += 1
                pending[kind] = (key, t, array)
                frame = complete()
                if frame is not None:
                    yield frame
        if index == 0 and not pending:
            raise SourceError(f"mkv: {self.path} holds no complete colour or depth frame "
                              "(an empty or truncated recording)")
        for kind, (_, t, _) in sorted(pending.items(), key=lambda kv: kv[1][0]):
            yield SkippedFrame(index, t, f"{self.path.name}: the recording ends without the "
                                         f"{'COLOR' if kind == 'depth' else 'DEPTH'} frame for the "
                                         f"{kind.upper()} frame at {t} ns")
            index += 1

    def close(self) -> None:
        container = getattr(self, "_container", None)
        if container is not None:
            container.close()
            self._container = None
