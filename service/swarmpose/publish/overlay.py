"""The overlay video: the tracked skeletons drawn over the colour frames, as an MP4.

:class:`OverlaySink` draws, per frame message, every body with :func:`draw_bodies` over the
colour image (a turbo colour map of the depth where the frame has no colour), plus a line
of text (:func:`caption`). Every body is drawn as the links of
:data:`~swarmpose.body.skeleton.EVAL_LINKS` and a dot per evaluation joint at the joint's
``pixel``:

* one body: white links and dots coloured by confidence (green = 1 .. red = 0); caption
  ``frame N  state  latency ms  reason``;
* several bodies: links and dots in the body's id colour (:func:`id_color`, a fixed
  palette indexed by id, unlike the confidence colours and each other) and its id written
  beside its head; caption ``frame N  K people  latency ms``.

A skipped frame (no :class:`~swarmpose.sources.base.Frame`) repeats the previous image with
the reason written on it.

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
ID_PALETTE: tuple[tuple[int, int, int], ...] = (
    (0, 114, 255),    # azure
    (255, 0, 255),    # magenta
    (0, 255, 255),    # cyan
    (255, 150, 200),  # pink
    (150, 80, 255),   # violet
    (0, 150, 130),    # teal
    (150, 80, 30),    # brown
    (120, 0, 140),    # purple
)
"""RGB of body ids 0, 1, 2, ... when several bodies are drawn (id modulo its length). Every pair is
more than 120 apart in RGB (Euclidean, 0..255 per channel), and each is more than 100 from every
confidence colour and from the white links and text and black."""
LABEL_JOINTS = ("head", "neck")
"""Joints beside which a body's id is written, the first one with a pixel."""


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


def _pixels(body: dict, scale: tuple[float, float]) -> dict[str, tuple[int, int]]:
    """The drawable joint pixels of one body entry, times ``scale``: name -> (x, y) px."""
    joints = body.get("joints") or {}
    points: dict[str, tuple[int, int]] = {}
    for name in EVAL_JOINTS:
        pixel = (joints.get(name) or {}).get("pixel")
        if pixel is not None and all(np.isfinite(pixel)) and max(abs(pixel[0]), abs(pixel[1])) < 1e5:
            points[name] = (int(round(pixel[0] * scale[0])), int(round(pixel[1] * scale[1])))
    return points


def _sizes(image: np.ndarray) -> tuple[int, int]:
    """Line thickness and dot radius (px) for an image of this size."""
    size = min(image.shape[:2])
    return max(2, round(size / 240)), max(3, round(size / 100))


def draw_skeleton(image: np.ndarray, body: dict, scale: tuple[float, float] = (1.0, 1.0),
                  color: tuple[int, int, int] | None = None) -> np.ndarray:
    """Draw one body entry of a frame message onto ``image`` (H, W, 3) uint8 RGB, in place.

    Joint pixels (px of the colour image) are multiplied by ``scale`` (sx, sy); joints
    without a pixel are left out, and so are the links that touch them. ``color`` None:
    white links and dots coloured by confidence; an RGB colour: links and dots in it (the
    dots ringed in black).
    """
    import cv2

    thickness, radius = _sizes(image)
    joints = body.get("joints") or {}
    points = _pixels(body, scale)
    for a, b in EVAL_LINKS:
        if a in points and b in points:
            cv2.line(image, points[a], points[b], LINK_COLOR if color is None else color, thickness, cv2.LINE_AA)
    for name, point in points.items():
        if color is None:
            cv2.circle(image, point, radius, confidence_color(joints[name].get("confidence", 0.0)), -1, cv2.LINE_AA)
        else:
            cv2.circle(image, point, radius + 1, (0, 0, 0), -1, cv2.LINE_AA)
            cv2.circle(image, point, radius, color, -1, cv2.LINE_AA)
    return image


def id_color(body_id: int) -> tuple[int, int, int]:
    """RGB of body ``body_id`` (>= 0) in the overlay: :data:`ID_PALETTE` indexed by id, cycling."""
    return ID_PALETTE[int(body_id) % len(ID_PALETTE)]


def label_anchor(body: dict, scale: tuple[float, float] = (1.0, 1.0)) -> tuple[int, int] | None:
    """Where a body's id is written (x, y) px: its head joint, else its neck, else its highest
    drawn joint; None when no joint has a pixel."""
    points = _pixels(body, scale)
    for name in LABEL_JOINTS:
        if name in points:
            return points[name]
    return min(points.values(), key=lambda p: p[1]) if points else None


def _label(image: np.ndarray, text: str, anchor: tuple[int, int], color: tuple[int, int, int]) -> None:
    """``text`` in ``color`` with a 2 px black outline, up and right of ``anchor`` (x, y) px, in place.

    The outline is the text's mask dilated (OpenCV draws Hershey text no thicker than 2 px)."""
    import cv2

    _, radius = _sizes(image)
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, max(0.5, min(image.shape[:2]) / 600)
    (width, height), base = cv2.getTextSize(text, font, scale, 2)
    rows, cols = image.shape[:2]
    x = int(np.clip(anchor[0] + radius + 2, 0, max(0, cols - width)))
    y = int(np.clip(anchor[1] - radius - 2, height + 2, max(height + 2, rows - base - 2)))
    x0, y0, x1, y1 = max(x - 4, 0), max(y - height - 4, 0), min(x + width + 4, cols), min(y + base + 4, rows)
    if x0 >= x1 or y0 >= y1:
        return
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.putText(mask, text, (x - x0, y - y0), font, scale, 255, 2, cv2.LINE_AA)
    outline = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    roi = image[y0:y1, x0:x1].astype(np.float32) * (1 - outline[..., None] / 255.0)
    alpha = mask[..., None] / 255.0
    image[y0:y1, x0:x1] = np.round(roi * (1 - alpha) + np.asarray(color, np.float32) * alpha).astype(np.uint8)


def draw_bodies(image: np.ndarray, bodies: list[dict], scale: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Draw every body entry of a frame message onto ``image`` (H, W, 3) uint8 RGB, in place.

    ``bodies``: the message's ``bodies`` list; joint pixels (px) are multiplied by ``scale``
    (sx, sy). One body: white links, confidence-coloured dots (:func:`draw_skeleton`).
    Several: each in its id colour (:func:`id_color`) with its id written beside its head
    (:func:`label_anchor`); a body without any joint pixel draws nothing.
    """
    if len(bodies) == 1:
        return draw_skeleton(image, bodies[0], scale)
    for k, body in enumerate(bodies):
        body_id = body.get("id")
        if isinstance(body_id, bool) or not isinstance(body_id, (int, np.integer)) or body_id < 0:
            body_id = k  # not a protocol id: colour it by its place in the list
        color = id_color(body_id)
        draw_skeleton(image, body, scale, color)
        anchor = label_anchor(body, scale)
        if anchor is not None:
            _label(image, str(body_id), anchor, color)
    return image


def caption(message: dict, skipped: bool = False) -> str:
    """The text line of a frame: ``frame N  state  latency ms  reason`` for one body (state
    ``no body`` for a frame without bodies; ``person K`` after the state when its id K is not
    0), ``frame N  K people  latency ms  reason`` for several (``K people (L lost)`` when L of
    them are lost); ``frame N  skipped  reason`` for one the source could not deliver."""
    bodies = message.get("bodies") or []
    several = len(bodies) > 1
    reason = (bodies[0].get("reason") if bodies and not several else "") or message.get("reason", "")
    if skipped:
        return f"frame {message.get('frame', '?')}  skipped" + (f"  {reason}" if reason else "")
    if several:
        lost = sum(body.get("state") == "lost" for body in bodies)
        state = f"{len(bodies)} people" + (f" ({lost} lost)" if lost else "")
    elif bodies:
        body_id = bodies[0].get("id", 0)
        state = bodies[0].get("state", "") + (f"  person {body_id}" if body_id != 0 else "")
    else:
        state = "no body"
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
            draw_bodies(image, message.get("bodies") or [], scale)
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
