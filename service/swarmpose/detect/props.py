"""Props beside people: surfaces that are not a person but lie within a person's reach (a table in
front of someone, the stool they stood up from), found in the depth segmentation and remembered
while they stay where they are.

Why it matters: the depth term (:mod:`swarmpose.tracking.objective`) rewards the model for
covering any observed pixel within T = 0.3 m of its surface, and a limb the detector does not see
(legs behind a table) or sees weakly (a leg beside a stool) is pulled into such a surface: the
MakeHuman sit-stand clip with a table tracked its legs lying inside the table top, with a stool
seen from the side its near leg on the stool's face (BENCHMARKS.md, issue 53).

What is done with them: **background, left out of the person's depth** (set to no measurement,
as another person's pixels are, :mod:`swarmpose.people.people_tracker`). Neither covering nor
leaving such a pixel then costs the model anything, so nothing pulls the body into the prop, and a
hidden keypoint no longer lifts onto it (a keypoint without depth leaves the 3D term). The
alternative, an occluder term that lets the body hide behind the prop but penalises it in front of
it, would keep a little more evidence, but it needs a third kind of pixel in the OpenCL scorer;
zeroing uses the one every part of the tracker already treats as unobserved.

How they are found:

* **In one frame** (:func:`props_beside`): a surface the segmentation turned down as a person for
  its shape (:data:`PROP_REASONS`: too short, too low, too narrow or flat; not a speck or a
  fragment, ``too_small``, not background seen through a gap, ``in_gap``, and not the large
  surfaces of the room, ``too_wide``, ``too_tall``, ``too_high``) whose box comes within
  :data:`REACH_M` of a person's box in the image (at the person's depth) and whose depth range
  comes within :data:`REACH_M` of the person's.
* **Over frames** (:class:`PropMemory`): such a candidate becomes a prop once it has stood at the
  same place and depth for :data:`CONFIRM_FRAMES` frames running in which someone is found (a
  person's legs seen below another person are turned down as too low now and then, but move: in
  the synthetic benchmark sequences without props such a candidate never lasted two frames); its
  depth is remembered (a running mean), and in later frames a pixel whose depth matches the
  remembered one (within :func:`match_tolerance`, about 3 sensor noise sigmas) is the prop still
  standing there. Those pixels are left out of the segmentation's foreground, as the floor is, so a
  person who sits down on a stool seen before gets a segment without the stool, and out of every
  person's depth.

Limits: a prop is known only once it has been seen apart from every person for
:data:`CONFIRM_FRAMES` frames: a stool that someone sits on from the first frame, or stands astride
while sitting down, is merged into their segment (it touches them at their depth) and stays in
their depth until they stand up and step away. A prop that is moved is a new surface where it goes;
a pixel of its old place is forgotten once something farther is seen there. A moving camera makes
the memory useless (nothing matches); one with another intrinsics starts a new one.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.detect.depth_surfaces import Piece, SurfaceFrame

PROP_REASONS = ("too_short", "too_low", "too_narrow", "flat")
"""Rejections of surfaces that may be furniture beside a person (see the module docstring)."""
CONFIRM_FRAMES = 5
"""A candidate becomes a prop after this many frames running at the same place and depth (frames
where the segmentation finds nobody do not count, nor break the run: nothing is beside no one)."""
REACH_M = 1.0
"""A prop lies within this (m) of a person: in the image at the person's depth, and in depth."""
MATCH_BASE_M = 0.015
MATCH_PER_M2 = 0.004
"""A pixel shows a remembered prop when its depth z (m) is within MATCH_BASE_M + MATCH_PER_M2 z^2
of the remembered depth: 3.1 cm at 2 m, 5.1 cm at 3 m, 7.9 cm at 4 m, about three times a
Kinect's axial noise there (1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2)."""


def match_tolerance(z: np.ndarray) -> np.ndarray:
    """The largest difference (m) between a depth z (m) and a remembered prop's depth there that
    still counts as the prop."""
    return MATCH_BASE_M + MATCH_PER_M2 * z * z


def _depth_range(frame: SurfaceFrame, piece: Piece) -> tuple[float, float]:
    """The 2nd and 98th percentile (m) of a piece's depth (on every ``cfg.stride``-th pixel)."""
    p = frame.coords(piece, frame.cfg.stride)
    lo, hi = np.percentile(frame.depth[p.v, p.u], [2.0, 98.0])
    return float(lo), float(hi)


def props_beside(frame: SurfaceFrame, rejected: list[Piece], people: list[Piece]) -> np.ndarray | None:
    """(H, W) bool: the pixels of the rejected surfaces that are props beside one of ``people``
    (see the module docstring: a rejection of :data:`PROP_REASONS` whose box comes within
    :data:`REACH_M` of the person's in the image, at the person's depth, and whose depth range comes
    within :data:`REACH_M` of the person's), or None when there are none."""
    out = None
    H, W = frame.depth.shape
    candidates = [q for q in rejected if q.reason in PROP_REASONS and q.stats.get("points", 0) >= 8]
    if not candidates or not people:
        return None
    ranges = [_depth_range(frame, person) for person in people]
    for piece in candidates:
        lo, hi = _depth_range(frame, piece)
        for person, (plo, phi) in zip(people, ranges):
            reach = REACH_M * frame.intrinsics.fx / float(person.stats["centroid"][2])
            b, q = person.box, piece.box
            if (max(lo - phi, plo - hi) <= REACH_M and q[0] < b[2] + reach and b[0] - reach < q[2]
                    and q[1] < b[3] + reach and b[1] - reach < q[3]):
                if out is None:
                    out = np.zeros((H, W), bool)
                out[q[1]:q[3], q[0]:q[2]] |= piece.mask
                break
    return out


class PropMemory:
    """The props of one fixed camera, remembered from frame to frame (see the module docstring).

    A pixel of a candidate (:func:`props_beside`) becomes a prop once it has been one, at the same
    depth (:func:`match_tolerance`), in :data:`CONFIRM_FRAMES` frames running: the visible legs of a
    person hidden behind another are turned down as too low for a frame or two, and move."""

    def __init__(self) -> None:
        self.intrinsics: Intrinsics | None = None
        self._sum: np.ndarray | None = None  # (H, W) float64: sum of the depths seen as a candidate, m
        self._count: np.ndarray | None = None  # (H, W) int32: frames running (a prop: CONFIRM_FRAMES or more)

    @property
    def empty(self) -> bool:
        """Whether the memory holds nothing: no prop and no pixel on its way to being one."""
        return self._count is None

    def _mean(self) -> np.ndarray:
        """(H, W) float32: the remembered depth (m), 0 where none."""
        out = np.zeros(self._count.shape, np.float32)
        seen = self._count > 0
        out[seen] = self._sum[seen] / self._count[seen]
        return out

    def known(self, depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray | None:
        """(H, W) bool: the pixels of ``depth`` (m, 0 = none) that show a confirmed prop, or None
        when none does (or the camera is another than the memory's, which is then forgotten).
        A prop pixel seen through (something farther is seen there) is forgotten."""
        if self.intrinsics is not None and self.intrinsics != intrinsics:
            self.__init__()
        if self._count is None:
            return None
        props = self._count >= CONFIRM_FRAMES
        if not props.any():
            return None
        remembered = self._mean()
        tolerance = match_tolerance(remembered)
        gone = props & (depth > remembered + tolerance)
        self._sum[gone], self._count[gone] = 0.0, 0
        out = props & ~gone & (depth > 0) & (np.abs(depth - remembered) <= tolerance)
        return out if out.any() else None

    def learn(self, depth: np.ndarray, intrinsics: Intrinsics, candidates: np.ndarray | None) -> None:
        """Count this frame's candidate pixels ``candidates`` (H, W) bool of ``depth`` (H, W) m: a
        pixel not yet a prop starts again where it is no candidate or its depth moved."""
        if candidates is None and self._count is None:
            return
        if self._count is None:
            self.intrinsics = intrinsics
            self._sum = np.zeros(depth.shape, np.float64)
            self._count = np.zeros(depth.shape, np.int32)
        now = np.zeros(depth.shape, bool) if candidates is None else candidates & (depth > 0)
        remembered = self._mean()
        same = now & (self._count > 0) & (np.abs(depth - remembered) <= match_tolerance(remembered))
        pending = self._count < CONFIRM_FRAMES
        restart = pending & ~same  # not a candidate now, or moved: counting starts again
        self._sum[restart], self._count[restart] = 0.0, 0
        grow = now & (same | restart)
        self._sum[grow] += depth[grow]
        self._count[grow] += 1
        if not self._count.any():  # nothing pending or known: no memory to keep up
            self.__init__()
