"""The frame-source protocol shared by every reader.

A :class:`Frame` is one synchronised RGBD capture in swarmpose's conventions: depth float32
metres with 0 = no measurement, colour uint8 RGB of the same size (depth registered to
colour), the pinhole intrinsics of both, the capture time in ns and the frame index.
A :class:`FrameSource` yields frames (or :class:`SkippedFrame` where one could not be read);
it is a context manager and an iterator.

Failure policy (every source): a source that cannot be opened raises
:class:`~swarmpose.core.errors.SourceError` (or ``ConfigError`` for a malformed URI) from its
constructor, and so does a failure before the first frame. Once a frame has been delivered,
a failure never raises into the caller: a single unreadable frame is yielded as a
:class:`SkippedFrame` (logged as a warning naming its reason, the first
:data:`SKIP_WARNINGS` of a pass) and iteration goes on; a failure of the whole source (file truncated,
device gone, reads timing out) ends the iteration with ``status`` set to ``"error: …"``, and
so does a pass that yielded only skipped frames (nothing in the source could be read).
Live devices first try to reconnect, at most :data:`MAX_RECONNECTS` times, yielding a
:class:`SkippedFrame` for each failed read. :meth:`FrameSource.__iter__` enforces this for
every subclass.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SourceError, SwarmposeError

MAX_RECONNECTS = 3
"""How often a live source tries to reopen its device after a failed read before it gives up."""
CAPTURE_RETRIES = 10
"""Consecutive empty captures (no frame ready yet) of a live source that count as one failed read."""
SKIP_WARNINGS = 10
"""Skipped frames of one pass over a source that are logged one by one (with the file or failure)."""
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    """One RGBD frame.

    depth: (H, W) float32 metres, 0 = invalid; color: (H, W, 3) uint8 RGB or None;
    intrinsics: pinhole of both images (depth is registered to colour);
    timestamp_ns: capture time (ns, source clock); index: 0-based frame number in the source.
    """

    index: int
    timestamp_ns: int
    depth: np.ndarray
    color: np.ndarray | None
    intrinsics: Intrinsics

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.depth.shape[1]), int(self.depth.shape[0])


@dataclass(frozen=True)
class SkippedFrame:
    """A frame the source could not deliver (missing or corrupt file, dropped by the device).

    Sources yield it in place of the :class:`Frame` so consumers can report the frame as
    skipped, with ``reason`` naming the file or the failure, and go on.
    """

    index: int
    timestamp_ns: int
    reason: str


@dataclass(frozen=True)
class DeferredFrame:
    """A frame of a recording whose images are not read yet: its index, capture time, and
    ``read()``, which reads them (a :class:`Frame`, or a :class:`SkippedFrame` saying why not).

    Served at its rate (``serve``), a recording's frames come faster than the tracker takes them
    and most are dropped; a source with ``can_defer`` yields these while ``defer`` is set, so that
    only the frames the tracker takes are decoded."""

    index: int
    timestamp_ns: int
    read: Callable[[], Frame | SkippedFrame]


class FrameSource:
    """Base class of frame sources. Subclasses implement :meth:`_frames` and may override :meth:`close`.

    Attributes: ``uri`` (what the user passed to ``--source``), ``length`` (frames, None when
    unknown or live), ``status`` (a short human-readable state: "open", "ended", "error: …"),
    ``live`` (a camera delivering frames in real time, not a recording).
    """

    uri: str = ""
    length: int | None = None
    status: str = "open"
    live: bool = False
    rate_known: bool = True
    """False when the source's frame rate (``fps``) and timestamps were assumed, not recorded."""
    can_defer: bool = False
    defer: bool = False
    """With ``can_defer``: yield :class:`DeferredFrame` items instead of frames (see there)."""

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        raise NotImplementedError

    def __iter__(self) -> Iterator[Frame | SkippedFrame]:
        """The frames of :meth:`_frames` under the failure policy of this module's docstring."""
        delivered, skipped, first_skip = False, 0, None
        try:
            for item in self._frames():
                delivered = delivered or isinstance(item, (Frame, DeferredFrame))
                if isinstance(item, SkippedFrame):
                    skipped += 1
                    first_skip = first_skip or item
                    warn_skipped(self.uri or type(self).__name__, item, skipped)
                yield item
        except Exception as exc:  # the policy: nothing escapes after the first frame
            message = exc_message(exc)
            if not delivered:
                self.status = f"error: {message}"
                if isinstance(exc, SwarmposeError):
                    raise
                raise SourceError(f"{self.uri or type(self).__name__}: {message}") from exc
            self.status = f"error: {message}"
            return
        if first_skip is not None and not delivered:  # it ran, but nothing in it could be read
            self.status = (f"error: none of its {skipped} frames could be read (frame {first_skip.index}: "
                           f"{first_skip.reason})")
        if not self.status.startswith("error"):
            self.status = "ended"

    def close(self) -> None:
        """Release files and devices; safe to call twice."""

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def warn_skipped(name: str, item: SkippedFrame, count: int) -> None:
    """Log the ``count``-th skipped frame of source ``name`` as a warning naming its reason; after
    :data:`SKIP_WARNINGS` of them, once, that further ones are only counted."""
    if count <= SKIP_WARNINGS:
        log.warning("%s: frame %d skipped: %s", name, item.index, item.reason)
    elif count == SKIP_WARNINGS + 1:
        log.warning("%s: more frames skipped; the run's summary and status messages count them, "
                    "the frames' messages say why", name)


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def exc_message(exc: BaseException) -> str:
    """One line from an exception (Open3D's colour codes and source locations, and an error number
    before the text, removed)."""
    text = _ANSI.sub("", str(exc)).strip() or type(exc).__name__
    text = re.sub(r"^\[Open3D \w+\] .*? \S+\.(?:cpp|h):\d+: ", "", text, flags=re.S)
    text = re.sub(r"^\[Errno -?\d+\] ", "", text)  # FFmpeg's error codes as errno numbers mean nothing to a user
    return " ".join(text.split())


def live_frames(name: str, capture: Callable[[int], Frame | SkippedFrame | None], reopen: Callable[[], None],
                 ) -> Iterator[Frame | SkippedFrame]:
    """The capture loop of a live device with the failure policy of :mod:`.base`.

    ``capture(index)`` returns a frame, None when none was ready, or raises; ``reopen()``
    closes and reopens the device (raising when it cannot).
    """
    index, empty, failures = 0, 0, 0
    while True:
        try:
            frame = capture(index)
        except Exception as exc:  # a failed read of any kind counts towards the reconnects
            frame, reason = None, exc_message(exc)
        else:
            reason = None
            if frame is None:
                empty += 1
                if empty < CAPTURE_RETRIES:
                    continue
                reason = f"no frame in {CAPTURE_RETRIES} captures"
        if frame is not None:
            empty = failures = 0
            yield frame
            index += 1
            continue
        empty = 0
        failures += 1
        if failures > MAX_RECONNECTS:
            raise SourceError(f"{name}: gave up after {MAX_RECONNECTS} reconnects ({reason})")
        yield SkippedFrame(index, time.monotonic_ns(), f"{name}: {reason}; reconnecting ({failures}/{MAX_RECONNECTS})")
        index += 1
        try:
            reopen()
        except Exception as exc:
            if failures >= MAX_RECONNECTS:
                raise SourceError(f"{name}: cannot reopen the device ({exc_message(exc)})") from exc
            time.sleep(1.0)
