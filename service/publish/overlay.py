"""The overlay video: the tracked skeleton drawn over the colour frames, as an MP4.

:class:`OverlaySink` draws, per frame message, the links of
:data:`~swarmpose.body.skeleton.EVAL_LINKS` and a dot per evaluation joint (at the joint's
``pixel``, coloured by its confidence: green = 1 .. red = 0) of the message's first body
over the colour image (a turbo colour map of the depth where the frame has no colour),
plus a line of text: frame number, state, latency and the reason, if any. A skipped frame
(no :class:`~swarmpose.sources.base.Frame`) repeats the previous image with the reason
written on it.

The MP4 is fragmented, one fragment per frame, and flushed after every frame, so a file
whose writer was killed still plays up to its last frame but one. Codec: H.264 (libx264,
``tune=zerolatency`` so that every frame leaves the encoder at once) where PyAV has that
encoder, else MPEG-4 part 2; yuv420p; the size of the first frame, rounded down to even.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS, EVAL_LINKS
from swarmpose.core.errors import OutputError
from swarmpose.sources.base import Frame, exc_message

CONTAINER_OPTIONS = {"movflags": "frag_every_frame+empty_moov+default_base_moof", "flush_packets": "1"}
"""Fragmented MP4, one fragment per frame, written through at once: playable if the process dies."""
DEPTH_RANGE_M = (0.3, 6.0)
"""Depth (m) mapped onto the colour map's ends when a frame has no colour image."""
LINK_COLOR = (255, 255, 255)
TEXT_COLOR = (255, 255, 255)


def video_codec() -> str:
    """``libx264`` when PyAV can encode H.264 with it, else ``mpeg4``."""
    import av

    try:
        av.Codec("libx264", "w")
    except Exception:  # PyAV raises different errors for unknown codecs across versions
        return "mpeg4"
    return "libx264"


def confidence_color(confidence: float) -> tuple[int, int, int]:
    """RGB of a joint with ``confidence`` in 0..1: red (0) through yellow to green (1)."""
    c = float(np.clip(confidence, 0.0, 1.0))
    return int(round(255 * min(1.0, 2 * (1 - c)))), int(round(255 * min(1.0, 2 * c))), 0


def background(frame: Frame) -> np.ndarray:
    """(H, W, 3) uint8 RGB to draw on: a copy of the colour image, else the depth as a colour map
    (turbo over :data:`DEPTH_RANGE_M`, black where there is no measurement)."""
    import cv2

    if frame.color is not None:
        return np.ascontiguousarray(frame.color[..., :3], dtype=np.uint8).copy()
    depth = np.asarray(frame.depth, dtype=np.float32)
    lo, hi = DEPTH_RANGE_M
    scaled = np.clip((depth - lo) / (hi - lo), 0.0, 1.0)
    image = cv2.applyColorMap((255 * (1 - scaled)).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1].copy()
    image[~(depth > 0)] = 0
    return image


def _text(image: np.ndarray, text: str) -> None:
    """White ``text`` on a black box at the top left of ``image``, in place."""
    import cv2

    scale = max(0.4, image.shape[0] / 960)
    (width, height), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(image, (0, 0), (width + 10, height + base + 8), (0, 0, 0), -1)
    cv2.putText(image, text, (5, height + 4), cv2.FONT_HERSHEY_SIMPLEX, scale, TEXT_COLOR, 1, cv2.LINE_AA)


def draw_skeleton(image: np.ndarray, body: dict, scale: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Draw one body entry of a frame message onto ``image`` (H, W, 3) uint8 RGB, in place.

    Joint pixels (px of the colour image) are multiplied by ``scale`` (sx, sy); joints
    without a pixel are left out, and so are the links that touch them.
    """
    import cv2

    size = min(image.shape[:2])
    thickness, radius = max(2, round(size / 240)), max(3, round(size / 100))
    joints = body.get("joints") or {}
    points: dict[str, tuple[int, int]] = {}
    for name in EVAL_JOINTS:
        pixel = (joints.get(name) or {}).get("pixel")
        if pixel is not None and all(np.isfinite(pixel)) and max(abs(pixel[0]), abs(pixel[1])) < 1e5:
            points[name] = (int(round(pixel[0] * scale[0])), int(round(pixel[1] * scale[1])))
    for a, b in EVAL_LINKS:
        if a in points and b in points:
            cv2.line(image, points[a], points[b], LINK_COLOR, thickness, cv2.LINE_AA)
    for name, point in points.items():
        cv2.circle(image, point, radius, confidence_color(joints[name].get("confidence", 0.0)), -1, cv2.LINE_AA)
    return image


def caption(message: dict, skipped: bool = False) -> str:
    """The text line of a frame: ``frame N  state  latency ms  reason`` (state ``no body`` for a
    frame without bodies); ``frame N  skipped  reason`` for one the source could not deliver."""
    bodies = message.get("bodies") or []
    reason = (bodies[0].get("reason") if bodies else "") or message.get("reason", "")
    if skipped:
        return f"frame {message.get('frame', '?')}  skipped" + (f"  {reason}" if reason else "")
    state = bodies[0].get("state", "") if bodies else "no body"
    parts = [f"frame {message.get('frame', '?')}", state, f"{float(message.get('latency_ms', 0.0)):.1f} ms"]
    return "  ".join(parts + ([reason] if reason else []))


class OverlaySink:
    """Writes the overlay MP4 at ``path`` (see the module docstring); ``fps`` frames per second.

    Raises :class:`~swarmpose.core.errors.OutputError` naming the file when it cannot be created
    or written. A sink closed before its first frame leaves no file behind.
    """

    def __init__(self, path: str | Path, fps: float = 30.0) -> None:
        import av

        if not (np.isfinite(fps) and fps > 0):
            raise OutputError(f"overlay video {path}: fps must be positive, got {fps}")
        self.path = Path(path)
        self.fps = float(fps)
        self.codec = video_codec()
        self.frames = 0
        self._stream = None
        self._last: np.ndarray | None = None
        self._closed = False
        try:
            self._file = open(self.path, "wb")  # held open until close()
        except OSError as exc:
            raise self._error(exc) from exc
        try:
            self._container = av.open(self._file, "w", format="mp4", container_options=CONTAINER_OPTIONS)
        except Exception as exc:  # FFmpeg errors are not all OSErrors
            self._file.close()
            raise self._error(exc) from exc

    def _error(self, exc: BaseException) -> OutputError:
        return OutputError(f"cannot write the overlay video {self.path}: {exc_message(exc)}; "
                           "choose a writable output folder with free space")

    def _open_stream(self, width: int, height: int) -> None:
        stream = self._container.add_stream(self.codec, rate=Fraction(self.fps).limit_denominator(1001))
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.codec_context.gop_size = max(1, int(round(self.fps)))
        if self.codec == "libx264":
            stream.codec_context.options = {"preset": "veryfast", "tune": "zerolatency", "crf": "20"}
        else:
            stream.codec_context.bit_rate = int(8 * width * height * self.fps / 10)  # ~0.8 bit per pixel
        self._stream = stream

    def _encode(self, image: np.ndarray | None) -> None:
        import av

        try:
            vframe = None
            if image is not None:
                vframe = av.VideoFrame.from_ndarray(image, format="rgb24")
                vframe.pts = self.frames
            for packet in self._stream.encode(vframe):
                self._container.mux(packet)
            self._file.flush()
        except Exception as exc:  # disk full, file gone: PyAV raises OSError or FFmpegError
            raise self._error(exc) from exc
        if image is not None:
            self.frames += 1

    def frame(self, message: dict, frame: Frame | None) -> None:
        """Draw and encode one frame (repeat the previous image for a skipped frame, if any)."""
        if self._closed:
            raise OutputError(f"overlay video {self.path} is closed; open a new sink to write more frames")
        if frame is None:
            if self._last is None:
                return
            image = self._last.copy()
        else:
            import cv2

            image = background(frame)
            height, width = image.shape[:2]
            if self._stream is None:
                self._open_stream(width - width % 2, height - height % 2)
            w, h = self._stream.width, self._stream.height
            scale = (1.0, 1.0)
            if (width - width % 2, height - height % 2) == (w, h):
                image = np.ascontiguousarray(image[:h, :w])
            else:  # the source changed size mid-stream: fit it to the video
                image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
                scale = (w / width, h / height)
            bodies = message.get("bodies") or []
            if bodies:
                draw_skeleton(image, bodies[0], scale)
            self._last = image.copy()
        _text(image, caption(message, skipped=frame is None))
        self._encode(image)

    def status(self, message: dict) -> None:
        """Status messages are not drawn."""

    def close(self) -> None:
        """Flush the encoder and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        error: OutputError | None = None
        try:
            if self._stream is not None:
                self._encode(None)
        except OutputError as exc:
            error = exc
        try:
            self._container.close()
        except Exception as exc:  # the trailer could not be written
            error = error or self._error(exc)
        finally:
            self._file.close()
            if self._stream is None:
                self.path.unlink(missing_ok=True)
        if error is not None:
            raise error
