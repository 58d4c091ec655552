"""People in one depth frame: one pixel mask per person, from depth alone.

Method (all in the camera frame: OpenCV axes, x right, y down, z forward, metres; pixels px):

1. **Foreground.** Pixels with a measurement between ``min_depth_m`` and ``max_depth_m`` that
   lie more than ``floor_clearance_m`` above the floor plane (:func:`fit_floor`, when one is
   found or given).
2. **Surfaces.** Connected components (OpenCV, 8-neighbours) of the foreground where a pixel is
   dropped if a neighbour is nearer by more than the step ``step_base_m + step_per_m2 * z^2``
   (grows with range like the Kinect's disparity quantisation). Two joined neighbours therefore
   never differ by more than one step, so a person in front of a wall or of another person
   comes out as their own component; the dropped one-pixel rim on the far side of each step is
   given back to the surface behind it when the masks are drawn.
3. **Measurements.** Each component's points (every ``stride``-th pixel) are measured along the
   floor's normal (height) and along the horizontal direction across the image (width; the
   camera's -y and x axes when there is no floor): robust width (2nd-98th percentile),
   head top and lowest point (the highest / lowest point with 3 more within 3 cm of it, so a
   stray pixel does not count and a far head of a few pixels is not cut short), vertical
   extent, frontal area (sum of pixel footprints z^2 / (fx fy)), median centre.
4. **Two people who touch.** The head-height profile across the component (highest point per
   3 cm column, smoothed) is searched for maxima standing ``head_dip_m`` above the dip between
   them, at least ``min_head_separation_m`` apart. Each pixel goes to the nearest head's
   vertical axis in the floor plane (across and along the view), and the split is kept only if
   every part is a person on its own (the tests of step 5) holding at least ``min_part_share``
   of the largest part's area, so a raised hand or arm is not taken for a second head; otherwise
   the weakest head is dropped and the rest tried again.
5. **Is it a person?** width ``min_width_m``..``max_width_m``, vertical extent
   ``min_vertical_m``..``max_vertical_m``, area at least ``min_area_m2`` and, with a floor, head
   top ``min_top_m``..``max_top_m`` above it; not flat (RMS distance of its points from their
   best plane at least ``min_relief_m``: a wall or door filling the view close up has the size
   of a person, but people measured here have 3.6-15 cm); and not background seen through a gap in a nearer
   surface (the wall between a person's arm and body: at least ``min_occluded_share`` of its
   outline next to something nearer by a depth step, and lying, within half a step, on the
   plane of a rejected large surface around it). Rejections are counted by reason in
   :attr:`Segmentation.rejected`.
6. **Fragments.** A piece too small to be a person (a hand or forearm split off by a depth
   step or a shadow) is added to the mask of the person who comes within ``attach_gap_m`` of it in the
   image, at a depth within ``attach_distance_m`` of the piece's depth range.
7. **Masks.** Pixels without a measurement enclosed by a person's mask (a closing with a
   disc of ``fill_m`` at the person's depth, at most ``max_fill_px``) are added to it, so the
   mask is the person's silhouette, not only the pixels with depth.

Limits: people closer than one depth step to each other *and* with heads at the same height
less than ``min_head_separation_m`` apart (one behind the other, hugging) stay one segment;
where two touching people are cut apart, a limb reaching towards the other person's axis (an
arm raised beside the neighbour's head) goes to the neighbour; a head or hand cut off from its
body by a nearer arm more than ``attach_gap_m`` wide stays out of the mask. A person touching
a wall or furniture at the same depth (leaning on it, sitting on a sofa) merges with it and is
rejected as too big, or keeps a piece of it; a person lying on the floor is too short.
Furniture with a person's size, a top 0.9-2.3 m high and some relief (a high-backed chair, a
coat stand) passes as a person; a flat person-sized board is only recognised as flat while the
sensor noise stays under ``min_relief_m`` (within about 3 m on a Kinect). Someone cut by the
image border is kept when what remains passes the tests (``touches_border`` says so), but their
height figures then refer to what is visible. With no floor in view the height tests use the
camera's axes, which assumes a roughly level camera. Far away a Kinect loses thin limbs to
dropped edge pixels: the mask's IoU with the true silhouette is 0.88 at 6 m and 0.7 at 7.5 m
(synthetic, simulated Kinect noise).
Time: 20-40 ms for a 640x480 frame on one core, about 5 ms of it fitting the floor (pass a
:class:`FloorPlane` found once for a fixed camera to save it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, check_shape
from swarmpose.detect.depth_surfaces import Coords, PeopleTuning, Piece, SurfaceFrame, supported_top
from swarmpose.detect.floor import FloorPlane, check_depth, fit_floor
from swarmpose.detect.peaks import find_peaks
from swarmpose.detect.person_masks import attach_fragments, finish_mask
from swarmpose.detect.props import props_beside

BORDER_PX = 2
"""A mask this close (px) to the edge of the image, or of a blank band along it, touches it."""

MAX_BLANK_BAND_PX = 32
"""Registered depth images have bands without depth along some edges (about 8-30 px on a
Kinect v1); an empty band up to this wide counts as the image's edge for ``touches_border``."""


@dataclass(frozen=True)
class PersonSegment:
    """One person.

    mask: (H, W) bool; box: (4,) int x0, y0, x1, y1 px, inclusive-exclusive (``mask[y0:y1,
    x0:x1]`` holds every pixel of the mask); centroid_m: (3,) camera frame, per-axis median of
    the person's points, m; top_m / bottom_m: height above the floor of the head top and of the
    lowest visible point, m (None without a floor; see the module docstring, step 3); width_m:
    horizontal extent across the view (2nd-98th percentile), m; height_extent_m: top minus
    lowest point (along the camera's -y without a floor), m; area_m2: frontal area of the
    pixels with depth, m^2; pixels: pixels in ``mask``; touches_border: the mask comes within
    BORDER_PX of the image's edge, or of a blank band (no depth) at most MAX_BLANK_BAND_PX wide
    along it, as registered depth images have: the person may be cut.
    """

    mask: np.ndarray
    box: np.ndarray
    centroid_m: np.ndarray
    top_m: float | None
    bottom_m: float | None
    width_m: float
    height_extent_m: float
    area_m2: float
    pixels: int
    touches_border: bool

    def as_dict(self) -> dict:
        """JSON-friendly summary (without the mask)."""
        def r(v):
            return None if v is None else round(float(v), 4)
        return {"box": [int(v) for v in self.box], "centroid_m": [r(v) for v in self.centroid_m],
                "top_m": r(self.top_m), "bottom_m": r(self.bottom_m), "width_m": r(self.width_m),
                "height_extent_m": r(self.height_extent_m), "area_m2": r(self.area_m2),
                "pixels": int(self.pixels), "touches_border": bool(self.touches_border)}


@dataclass(frozen=True)
class Segmentation:
    """The people of one frame.

    floor: the floor plane used (None: none in view or switched off); people: sorted left to
    right by box centre; labels: (H, W) int32, 0 = nobody, k = people[k - 1]; rejected: how
    many candidate surfaces were turned down, by reason (``too_small``, ``too_narrow``,
    ``too_wide``, ``too_short``, ``too_tall``, ``too_low``, ``too_high``, ``flat``, ``in_gap``,
    ``beyond_max_people``); specks under ``noise_area_m2`` are not counted; props: (H, W) bool, the
    pixels of rejected surfaces that are props beside a person (:func:`swarmpose.detect.props.props_beside`),
    None when there are none.
    """

    floor: FloorPlane | None
    people: tuple[PersonSegment, ...]
    labels: np.ndarray
    rejected: dict[str, int]
    props: np.ndarray | None = None

    def as_dict(self) -> dict:
        """JSON-friendly summary (without masks and labels)."""
        return {"floor": None if self.floor is None else self.floor.as_dict(),
                "people": [p.as_dict() for p in self.people], "rejected": dict(self.rejected)}


MAX_HEADS = 6
"""At most this many head candidates are tried when splitting one surface."""

BACKGROUND_REASONS = ("too_wide", "too_tall", "too_high")
"""Rejection reasons of large surfaces (walls, floors left over, furniture) that can be seen
through gaps between a person's limbs."""


def _in_gap(frame: SurfaceFrame, piece: Piece, backgrounds: list[Piece]) -> bool:
    """Whether an accepted piece is background seen through a gap in a nearer surface: much of
    its outline is occluded and it lies on the plane that a large rejected surface fits around
    it (within twice the piece's size), both within half a depth step."""
    c = frame.cfg
    if not backgrounds or frame.occluded_share(piece) < c.min_occluded_share:
        return False
    x0, y0, x1, y1 = piece.box
    w, h = x1 - x0, y1 - y0
    wx0, wy0, wx1, wy1 = x0 - w, y0 - h // 2, x1 + w, y1 + h // 2
    p = frame.coords(piece, c.stride)
    own = np.stack([p.h, p.across, p.along], -1)
    tol = 0.5 * float(frame.step(np.float32(piece.stats["centroid"][2])))
    for bg in backgrounds:
        b = bg.box
        ox0, oy0, ox1, oy1 = max(wx0, b[0]), max(wy0, b[1]), min(wx1, b[2]), min(wy1, b[3])
        if ox0 >= ox1 or oy0 >= oy1:
            continue
        win = np.s_[oy0:oy1:4, ox0:ox1:4]
        keep = bg.mask[oy0 - b[1]:oy1 - b[1]:4, ox0 - b[0]:ox1 - b[0]:4]
        z = frame.depth[win][keep]
        if z.size < 30:
            continue
        pts = np.stack([z * frame.height[win][keep], z * frame.across[win][keep], z * frame.along[win][keep]], -1)
        pts[:, 0] += frame.height_offset
        centre = pts.mean(axis=0)
        _, sv, vt = np.linalg.svd(pts - centre, full_matrices=False)
        if sv[-1] / np.sqrt(len(pts)) <= tol and np.median(np.abs((own - centre) @ vt[-1])) <= tol:
            return True
    return False


def _surfaces(frame: SurfaceFrame, background: np.ndarray | None = None) -> list[Piece]:
    """Steps 1-2: connected surfaces of the foreground whose neighbours differ by less than a
    depth step; pieces under ``noise_area_m2`` are dropped uncounted. ``background`` (H, W)
    bool: pixels left out of the foreground (known props)."""
    import cv2

    c, z = frame.cfg, frame.depth
    fg = (z > c.min_depth_m) & (z < c.max_depth_m)
    if background is not None:
        fg &= ~background
    if frame.floor is not None:
        fg &= z * frame.height > np.float32(c.floor_clearance_m - frame.height_offset)
    nearest = cv2.erode(np.where(fg, z, np.float32(np.inf)), np.ones((3, 3), np.uint8),
                        borderType=cv2.BORDER_REPLICATE)
    kept = fg & (nearest >= z - frame.step(z))
    count, labels, boxes, _ = cv2.connectedComponentsWithStats(kept.view(np.uint8), connectivity=8,
                                                              ltype=cv2.CV_32S)
    # frontal area per component, estimated on every other row and column (4x fewer pixels)
    sub = np.where(kept[::2, ::2], z[::2, ::2], 0)
    area = 4 * np.bincount(labels[::2, ::2].ravel(), weights=(sub * sub).ravel(), minlength=count)
    pieces = []
    for k in np.flatnonzero(area * frame.footprint >= c.noise_area_m2):
        if k > 0:
            x0, y0, w, h = (int(v) for v in boxes[k, :4])
            pieces.append(Piece((x0, y0, x0 + w, y0 + h), labels[y0:y0 + h, x0:x0 + w] == k,
                                 stats={"area_m2": float(area[k] * frame.footprint)}))
    return pieces


def height_profile(heights: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """(n_bins + 2,) the highest of ``heights`` (N,) m in each of the bins ``bins`` (N,) (0 ..
    n_bins - 1; the lowest height where a bin is empty), as a 3-bin mean with the edges repeated,
    between two bins at the lowest height."""
    heights = np.asarray(heights, dtype=np.float64)  # one dtype: ufunc.at on mixed ones is 30x slower
    low = float(heights.min())
    profile = np.full(bins.max() + 1, low, dtype=np.float64)
    np.maximum.at(profile, bins, heights)
    edged = np.concatenate([profile[:1], profile, profile[-1:]])
    return np.concatenate([[low], (edged[:-2] + edged[1:-1] + edged[2:]) / 3.0, [low]])


def _head_axes(frame: SurfaceFrame, p: Coords) -> list[tuple[float, float]]:
    """Step 4: heads (across, along) m of a piece, most prominent first, from the maxima of
    its head-height profile standing ``head_dip_m`` above the dips beside them."""
    c = frame.cfg
    start = float(p.across.min())
    bins = ((p.across - start) / c.profile_bin_m).astype(np.int64)
    padded = height_profile(p.h, bins)
    distance = max(1, int(np.ceil(c.min_head_separation_m / c.profile_bin_m)))
    peaks, prominence = find_peaks(padded, c.head_dip_m, distance)
    if frame.floor is not None:  # a head top stands at a person's height
        plausible = (padded[peaks] >= c.min_top_m) & (padded[peaks] <= c.max_top_m)
        peaks, prominence = peaks[plausible], prominence[plausible]
    axes = []
    for i in np.argsort(-prominence)[:MAX_HEADS]:
        centre = start + (peaks[i] - 0.5) * c.profile_bin_m
        head = (p.h >= padded[peaks[i]] - 0.25) & (np.abs(p.across - centre) <= 0.15)
        if head.any():
            axes.append((float(np.median(p.across[head])), float(np.median(p.along[head]))))
    return axes


def _split(frame: SurfaceFrame, piece: Piece) -> list[Piece]:
    """Step 4: the piece cut between the heads of people who touch, each pixel going to the
    nearest head's vertical axis; [piece] when no cut leaves only people."""
    c = frame.cfg
    axes = _head_axes(frame, frame.coords(piece, c.stride))
    if len(axes) < 2:
        return [piece]
    x0, y0, x1, y1 = piece.box
    rows, cols = np.nonzero(piece.mask)
    z = frame.depth[rows + y0, cols + x0]
    across, along = z * frame.across[rows + y0, cols + x0], z * frame.along[rows + y0, cols + x0]
    owner = np.full(piece.mask.shape, -1, np.int64)
    while len(axes) >= 2:
        centres = np.array(axes, dtype=np.float32)
        gaps = (across[:, None] - centres[:, 0]) ** 2 + (along[:, None] - centres[:, 1]) ** 2
        owner[rows, cols] = np.argmin(gaps, axis=-1)
        parts = [frame.judge(_crop(piece.box, owner == k)) for k in range(len(axes))]
        areas = np.array([part.stats["area_m2"] for part in parts])
        if all(part.reason is None for part in parts) and areas.min() >= c.min_part_share * areas.max():
            return parts
        axes.pop(int(np.argmin(areas)))
    return [piece]


def _crop(box: tuple[int, int, int, int], mask: np.ndarray) -> Piece:
    """A piece of ``mask`` (placed at ``box``) with its box shrunk to the mask."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return Piece((box[0], box[1], box[0], box[1]), mask[:0, :0])
    x0, y0 = box[0] + int(cols[0]), box[1] + int(rows[0])
    return Piece((x0, y0, box[0] + int(cols[-1]) + 1, box[1] + int(rows[-1]) + 1),
                  mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1])


def _sensor_area(depth: np.ndarray) -> tuple[int, int, int, int]:
    """Box (x0, y0, x1, y1) px, inclusive-exclusive, of the image less the blank bands (no
    depth) along its edges that are at most MAX_BLANK_BAND_PX wide."""
    H, W = depth.shape
    rows, cols = np.flatnonzero((depth > 0).any(axis=1)), np.flatnonzero((depth > 0).any(axis=0))

    def inset(first: int, last: int, size: int) -> tuple[int, int]:
        start = first if first <= MAX_BLANK_BAND_PX else 0
        end = last + 1 if size - 1 - last <= MAX_BLANK_BAND_PX else size
        return start, end

    x0, x1 = inset(int(cols[0]), int(cols[-1]), W)
    y0, y1 = inset(int(rows[0]), int(rows[-1]), H)
    return x0, y0, x1, y1


def _segment(frame: SurfaceFrame, mask: np.ndarray, sensor: tuple[int, int, int, int]) -> PersonSegment:
    """The public record of one person's finished mask (H, W)."""
    piece = _crop((0, 0), mask)
    s, box = frame.measure(piece), piece.box
    win = np.s_[box[1]:box[3], box[0]:box[2]]  # top and bottom from every pixel: a far head is a few pixels
    z = frame.depth[win][piece.mask]
    heights = z[z > 0] * frame.height[win][piece.mask][z > 0] + frame.height_offset
    s["top"], s["bottom"] = supported_top(heights), -supported_top(-heights)
    s["vertical"] = s["top"] - s["bottom"]
    touches = (box[0] < sensor[0] + BORDER_PX or box[1] < sensor[1] + BORDER_PX
               or box[2] > sensor[2] - BORDER_PX or box[3] > sensor[3] - BORDER_PX)
    with_floor = frame.floor is not None
    return PersonSegment(mask=mask, box=np.array(box, dtype=np.int64), centroid_m=s["centroid"],
                         top_m=s["top"] if with_floor else None, bottom_m=s["bottom"] if with_floor else None,
                         width_m=s["width"], height_extent_m=s["vertical"], area_m2=s["area_m2"],
                         pixels=int(np.count_nonzero(mask)), touches_border=bool(touches))


def _resolve_floor(floor, depth: np.ndarray, intrinsics: Intrinsics) -> FloorPlane | None:
    if isinstance(floor, str):
        if floor != "auto":
            raise ConfigError(f"segment_people: floor must be 'auto', None or a FloorPlane, got {floor!r}")
        return fit_floor(depth, intrinsics)
    if floor is not None and not isinstance(floor, FloorPlane):
        raise ConfigError(f"segment_people: floor must be 'auto', None or a FloorPlane, got {type(floor).__name__}")
    return floor


def segment_people(depth_m: np.ndarray, intrinsics: Intrinsics, *, floor: FloorPlane | None | str = "auto",
                   max_people: int = 6, background: np.ndarray | None = None, **tuning) -> Segmentation:
    """The people in one depth frame (see the module docstring for the method and its limits).

    depth_m: (H, W) metres, 0 or NaN = no measurement, registered to ``intrinsics``;
    floor: ``"auto"`` to fit it (:func:`fit_floor`), a :class:`FloorPlane` found before (a
    fixed camera: saves ~10 ms a frame), or None to work without one; max_people: at most this
    many people are kept, the largest by frontal area; background: (H, W) bool pixels that are
    no one's, left out as the floor is (the props a :class:`~swarmpose.detect.props.PropMemory`
    knows), None: none; tuning: overrides of
    :class:`PeopleTuning` fields. Raises ShapeError for a depth that is not
    (intrinsics.height, intrinsics.width) and ConfigError for a bad argument; a frame with
    nobody in it (empty, a wall, only floor) gives no people.
    """
    cfg = PeopleTuning.from_kwargs(tuning)
    if isinstance(max_people, bool) or not isinstance(max_people, (int, np.integer)) or max_people < 1:
        raise ConfigError(f"segment_people: max_people must be a positive integer, got {max_people!r}")
    depth = check_depth(depth_m, intrinsics)
    floor = _resolve_floor(floor, depth, intrinsics)
    labels = np.zeros(depth.shape, np.int32)
    if not (depth > 0).any():
        return Segmentation(floor, (), labels, {})
    frame = SurfaceFrame(depth, intrinsics, floor, cfg)
    people, rejected = [], []
    if background is not None:
        check_shape("background", background, depth.shape)
    for surface in _surfaces(frame, background):
        frame.judge(surface)
        splittable = (surface.reason in (None, "too_wide") and surface.stats["width"] >= 2 * cfg.min_width_m
                      and surface.stats["area_m2"] >= (1 + cfg.min_part_share) * cfg.min_area_m2)
        for piece in _split(frame, surface) if splittable else [surface]:
            (rejected if piece.reason else people).append(piece)
    backgrounds = [p for p in rejected if p.reason in BACKGROUND_REASONS]
    for piece in [p for p in people if _in_gap(frame, p, backgrounds)]:
        piece.reason = "in_gap"
        people.remove(piece)
        rejected.append(piece)
    reasons: dict[str, int] = {}
    rejected = attach_fragments(frame, people, rejected)
    for piece in rejected:
        reasons[piece.reason] = reasons.get(piece.reason, 0) + 1
    if len(people) > max_people:
        people.sort(key=lambda p: -p.stats["area_m2"])
        reasons["beyond_max_people"] = len(people) - max_people
        people = people[:max_people]
    people.sort(key=lambda p: p.stats["centroid"][2])  # nearest first: occluders claim shared pixels
    # every person's own pixels first, then what each adds; never the background
    taken = np.zeros(depth.shape, bool) if background is None else background.copy()
    for piece in people:
        taken[piece.box[1]:piece.box[3], piece.box[0]:piece.box[2]] |= piece.mask
    sensor = _sensor_area(depth)
    segments = []
    for piece in people:
        mask = finish_mask(frame, piece, taken)
        taken |= mask
        segments.append(_segment(frame, mask, sensor))
    segments.sort(key=lambda s: 0.5 * (s.box[0] + s.box[2]))
    for k, s in enumerate(segments, start=1):
        labels[s.mask] = k
    return Segmentation(floor, tuple(segments), labels, reasons, props_beside(frame, rejected, people))


__all__ = ["PeopleTuning", "PersonSegment", "Segmentation", "segment_people"]
