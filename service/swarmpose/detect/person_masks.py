"""The finishing half of :mod:`swarmpose.detect.people` (steps 6 and 7 of its docstring):
small rejected pieces (a hand split off by a depth step) given back to the person they
belong to, and each person's mask closed over the pixels without depth inside it.
"""

from __future__ import annotations

import numpy as np

from swarmpose.detect.depth_surfaces import Piece, SurfaceFrame


def attach_fragments(frame: SurfaceFrame, people: list[Piece], rejected: list[Piece]) -> list[Piece]:
    """Step 6: join each small rejected piece to the person whose mask comes within
    ``attach_gap_m`` of it in the image (measured at the piece's depth) with a depth within
    ``attach_distance_m`` of the piece's depth range there (the nearest such person); returns
    the pieces that stay rejected."""
    import cv2

    c, (H, W) = frame.cfg, frame.depth.shape
    left = []
    for piece in rejected:
        if piece.reason != "too_small":
            left.append(piece)
            continue
        z_piece = frame.depth[piece.box[1]:piece.box[3], piece.box[0]:piece.box[2]][piece.mask]
        z_piece = z_piece[z_piece > 0]
        gap = int(np.ceil(c.attach_gap_m * frame.intrinsics.fx / float(np.median(z_piece)))) if z_piece.size else 0
        x0, y0 = max(0, piece.box[0] - gap), max(0, piece.box[1] - gap)
        x1, y1 = min(W, piece.box[2] + gap), min(H, piece.box[3] + gap)
        if not any(x0 < b[2] and b[0] < x1 and y0 < b[3] and b[1] < y1 for b in (q.box for q in people)):
            left.append(piece)
            continue
        lo, hi = float(z_piece.min()), float(z_piece.max())
        outside = np.ones((y1 - y0, x1 - x0), np.uint8)
        outside[piece.box[1] - y0:piece.box[3] - y0, piece.box[0] - x0:piece.box[2] - x0][piece.mask] = 0
        near = cv2.distanceTransform(outside, cv2.DIST_L2, 3) <= gap
        best, best_gap = None, c.attach_distance_m
        for k, person in enumerate(people):
            b = person.box
            ox0, oy0, ox1, oy1 = max(x0, b[0]), max(y0, b[1]), min(x1, b[2]), min(y1, b[3])
            if ox0 >= ox1 or oy0 >= oy1:
                continue
            close = (person.mask[oy0 - b[1]:oy1 - b[1], ox0 - b[0]:ox1 - b[0]]
                     & near[oy0 - y0:oy1 - y0, ox0 - x0:ox1 - x0])
            z = frame.depth[oy0:oy1, ox0:ox1][close]
            z = z[z > 0]
            if z.size and (depth_gap := float(np.maximum(np.maximum(lo - z, z - hi), 0).min())) <= best_gap:
                best, best_gap = k, depth_gap
        if best is None:
            left.append(piece)
        else:
            people[best].mask, people[best].box = union(people[best], piece)
    return left


def union(a: Piece, b: Piece) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """The mask and box covering both pieces (``a`` keeps its measurements)."""
    x0, y0 = min(a.box[0], b.box[0]), min(a.box[1], b.box[1])
    x1, y1 = max(a.box[2], b.box[2]), max(a.box[3], b.box[3])
    mask = np.zeros((y1 - y0, x1 - x0), bool)
    for p in (a, b):
        mask[p.box[1] - y0:p.box[3] - y0, p.box[0] - x0:p.box[2] - x0] |= p.mask
    return mask, (x0, y0, x1, y1)


def finish_mask(frame: SurfaceFrame, piece: Piece, taken: np.ndarray) -> np.ndarray:
    """Step 7: the person's full-frame mask (H, W) bool: the piece, the one-pixel rim lost at
    depth steps where it continues the person's surface (above the floor), and enclosed pixels
    without depth;
    pixels in ``taken`` (another person's, or any person's own) are not added."""
    import cv2

    c = frame.cfg
    z = frame.depth
    fill = int(np.clip(round(c.fill_m * frame.intrinsics.fx / piece.stats["centroid"][2]), 0, c.max_fill_px))
    pad = max(1, fill)
    H, W = z.shape
    x0, y0 = max(0, piece.box[0] - pad), max(0, piece.box[1] - pad)
    x1, y1 = min(W, piece.box[2] + pad), min(H, piece.box[3] + pad)
    mask = np.zeros((y1 - y0, x1 - x0), bool)
    mask[piece.box[1] - y0:piece.box[3] - y0, piece.box[0] - x0:piece.box[2] - x0] = piece.mask
    zc, free = z[y0:y1, x0:x1], ~taken[y0:y1, x0:x1]
    kernel = np.ones((3, 3), np.uint8)
    lo = cv2.erode(np.where(mask, zc, np.float32(np.inf)), kernel)
    hi = cv2.dilate(np.where(mask, zc, np.float32(0)), kernel)
    step = frame.step(zc)
    rim = (zc > 0) & (zc >= lo - step) & (zc <= hi + step) & free
    if frame.floor is not None:  # never the floor around the feet
        rim &= zc * frame.height[y0:y1, x0:x1] + frame.height_offset > c.floor_clearance_m
    mask |= rim
    if fill > 0:
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * fill + 1,) * 2)
        closed = cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_CLOSE, disc).view(bool)
        mask |= closed & (zc <= 0) & free
    out = np.zeros((H, W), bool)
    out[y0:y1, x0:x1] = mask
    return out
