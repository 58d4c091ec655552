"""A clip's up axis and length unit: detected from the skeleton, or stated by the user.

* **Up axis**: the file axis along which the head stands above the ankles in most frames (the
  median over frames of the ankles' midpoint -> head direction, snapped to the nearest signed
  coordinate axis). A person lies down now and then, but not for most of a clip.
* **Units**: the unit that makes the standing reference pose (joints and End Sites, measured
  along the up axis) nearest a typical skeleton's 1.6 m, among :data:`UNITS`. Units this far
  apart cannot be confused for a person between about 1.1 and 2.3 m tall.

Retargeting itself is unit-free (it scales the root's motion by the ratio of leg lengths), so the
units say how big the captured person was; a stated unit that makes the person implausibly
small or large is an error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.core.errors import MotionError

UNITS = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
"""Unit name -> metres. ``cmu``: CMU's ASF length unit, 1/0.45 inch (about 5.6 cm)."""
TYPICAL_HEIGHT_M = 1.6
PLAUSIBLE_HEIGHT_M = (0.5, 2.6)
_AXES = "xyz"


@dataclass(frozen=True)
class ClipFrame:
    """up: the file's up axis, '+y', '-z', ...; units: a key of :data:`UNITS`; height: the
    standing reference pose's extent along ``up``, file units; stated: whether up / units came
    from the user rather than detection."""

    up: str
    units: str
    height: float
    up_stated: bool = False
    units_stated: bool = False

    @property
    def up_vector(self) -> np.ndarray:
        """The up axis as a unit vector (3,) in file coordinates."""
        return axis_vector(self.up)

    @property
    def height_m(self) -> float:
        """The reference pose's height in metres."""
        return self.height * UNITS[self.units]


def parse_up(text: str, where: str) -> str:
    """'y', '+Y', '-z' ... -> '+y' / '-z'; MotionError naming ``where`` otherwise."""
    t = text.strip().lower()
    sign = "-" if t.startswith("-") else "+"
    axis = t.lstrip("+-")
    if axis not in _AXES or len(axis) != 1:
        raise MotionError(f"{where}: up={text!r} is not an axis; write up=x, up=y or up=z (up=-z for a file "
                          "whose up is its -z)")
    return sign + axis


def parse_units(text: str, where: str) -> str:
    """A unit name of :data:`UNITS` (case-insensitive; 'inch'/'inches' = 'in'); MotionError otherwise."""
    t = text.strip().lower()
    t = {"inch": "in", "inches": "in", "metres": "m", "meters": "m", "centimetres": "cm"}.get(t, t)
    if t not in UNITS:
        raise MotionError(f"{where}: units={text!r} is not a unit; write one of {', '.join(UNITS)}")
    return t


def axis_vector(up: str) -> np.ndarray:
    """'+y' -> (0, 1, 0), '-z' -> (0, 0, -1)."""
    v = np.zeros(3)
    v[_AXES.index(up[1])] = 1.0 if up[0] == "+" else -1.0
    return v


def detect_up(head: np.ndarray, left_ankle: np.ndarray, right_ankle: np.ndarray) -> str:
    """The signed file axis nearest the median (over frames) direction from the ankles' midpoint
    to the head; inputs (N, 3) joint positions in file units."""
    rise = head - 0.5 * (left_ankle + right_ankle)
    rise = rise / np.maximum(np.linalg.norm(rise, axis=-1, keepdims=True), 1e-12)
    median = np.median(rise, axis=0)
    k = int(np.argmax(np.abs(median)))
    return ("+" if median[k] >= 0 else "-") + _AXES[k]


def detect_units(height: float) -> str:
    """The unit of :data:`UNITS` that makes ``height`` (file units) nearest 1.6 m, in ratio."""
    if not height > 0:
        raise MotionError("the skeleton has no height along its up axis; state its units (?units=cm)")
    return min(UNITS, key=lambda u: abs(np.log(height * UNITS[u] / TYPICAL_HEIGHT_M)))


def clip_frame(points: np.ndarray, up: str, up_stated: bool, units: str | None, where: str) -> ClipFrame:
    """The frame of a clip whose standing reference pose has ``points`` (K, 3) (joints and End
    Sites, file units) and whose up axis is ``up``; ``units`` as stated, or None to detect them.

    A stated unit that makes the person shorter or taller than 0.5..2.6 m is a MotionError naming
    ``where`` and the unit the skeleton's size suggests.
    """
    along = points @ axis_vector(up)
    height = float(along.max() - along.min())
    if units is None:
        return ClipFrame(up, detect_units(height), height, up_stated, False)
    metres = height * UNITS[units]
    lo, hi = PLAUSIBLE_HEIGHT_M
    if not lo <= metres <= hi:
        raise MotionError(f"{where}: in {units} its skeleton would stand {metres:.3g} m tall; its size suggests "
                          f"{detect_units(height)}: correct units= (or remove it to detect them)")
    return ClipFrame(up, units, height, up_stated, True)
