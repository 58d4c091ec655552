"""Holding a motion's frame: a person standing still, then moving on (``?hold=`` of a motion spec).

``?hold=SECONDS`` holds the motion's first frame for ``SECONDS`` s, then plays the motion on from
there; ``?hold=AT:SECONDS`` starts the motion ``AT`` s in (the frames before are skipped) and
holds its frame there. At ``fps`` frames a second, with ``k = round(AT * fps)`` and ``n =
round(SECONDS * fps)``, the held motion's frames are::

    frame i < n:   the motion's frame k          (the pose shown for exactly SECONDS s)
    frame i >= n:  the motion's frame k + 1 + (i - n)

so frame ``n`` is the first that moves, one frame period after the held frame, as the motion
itself would have gone on from it. Both a BVH clip (after it is retargeted and resampled) and a
built-in motion can be held.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmpose.core.errors import MotionError
from swarmpose.motion.sequence import Motion

MAX_HOLD_S = 600.0
"""The longest hold (s), and the latest start: ten minutes of a still person is 18000 frames at
30 fps, more than any benchmark or test renders."""
HOLD_HELP = ("write ?hold=SECONDS (hold the first frame) or ?hold=AT:SECONDS (hold the frame AT seconds into "
             "the motion), e.g. clip.bvh?hold=3 or builtin:walk?hold=0.5:3")


@dataclass(frozen=True)
class Hold:
    """at_s: where in the motion the held frame is (s from its start); seconds: how long it is held."""

    at_s: float
    seconds: float

    def frames(self, fps: float) -> tuple[int, int]:
        """(k, n): the held frame of the motion at ``fps`` and the number of frames it is held."""
        return int(round(self.at_s * fps)), int(round(self.seconds * fps))


def parse_hold(text: str, where: str) -> Hold:
    """``SECONDS`` or ``AT:SECONDS`` -> :class:`Hold`; MotionError naming ``where`` for anything
    else, a negative or non-finite number, or a hold or start beyond :data:`MAX_HOLD_S`."""
    parts = text.split(":")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        numbers = []
    if len(numbers) not in (1, 2) or not all(math.isfinite(x) for x in numbers):
        raise MotionError(f"{where}: hold={text!r} is not SECONDS or AT:SECONDS; {HOLD_HELP}")
    at_s, seconds = (0.0, numbers[0]) if len(numbers) == 1 else numbers
    if at_s < 0 or seconds <= 0:
        raise MotionError(f"{where}: hold={text!r}: the held time must be > 0 s and the start >= 0 s; {HOLD_HELP}")
    if max(at_s, seconds) > MAX_HOLD_S:
        raise MotionError(f"{where}: hold={text!r}: holds and starts are limited to {MAX_HOLD_S:g} s (a still "
                          f"person for longer makes no sequence worth rendering); hold for less")
    return Hold(at_s, seconds)


def motion_frames_needed(hold: Hold, frames: int, fps: float) -> int:
    """How many frames of a motion (from its start) a ``frames``-frame held sequence at ``fps`` uses."""
    k, n = hold.frames(fps)
    return k + 1 + max(int(frames) - n, 0)


def hold_motion(motion: Motion, hold: Hold, where: str) -> Motion:
    """``motion`` with its frame at ``hold.at_s`` held ``hold.seconds`` (module doc), at the motion's
    own frame rate; named ``NAME held S s at A s``. MotionError naming ``where`` when the hold is shorter
    than one frame or the held frame lies beyond the motion's end."""
    k, n = hold.frames(motion.fps)
    if n < 1:
        raise MotionError(f"{where}: hold {hold.seconds:g} s is less than one frame at {motion.fps:g} fps; hold for "
                          f"at least {1.0 / motion.fps:.3g} s")
    if k >= len(motion):
        raise MotionError(f"{where}: hold at {hold.at_s:g} s is past the motion's end ({len(motion)} frames, "
                          f"{motion.duration:.3g} s at {motion.fps:g} fps); hold a frame before "
                          f"{(len(motion) - 1) / motion.fps:.3g} s")
    index = np.concatenate([np.full(n, k), np.arange(k + 1, len(motion))])
    return Motion(f"{motion.name} held {hold.seconds:g} s at {hold.at_s:g} s", motion.fps,
                  motion.root_offset[index], motion.root_rotation[index], motion.angles[index])
