"""Turned crop regions (swarmpose.detect.regions) against hand-worked geometry and the axis-aligned crop."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.detect.onnx_pose import Square, crop_square, square_around
from swarmpose.detect.regions import MAX_REGIONS, MIN_RADIUS_PX, ROI_SCALE, RegionMemory, TurnedSquare, aligned_square


def _upright(square: Square) -> TurnedSquare:
    """The axis-aligned ``square`` as a region: its centre in pixel-centre coordinates, up = -y."""
    half = square.side / 2 - 0.5
    return TurnedSquare((square.x0 + half, square.y0 + half), float(square.side), (0.0, -1.0))


def test_an_upright_region_crops_and_maps_back_as_the_square_does():
    """Same side as the network's input: the crop is a pure shift, so both crops are the same pixels,
    and a crop coordinate maps to the same frame pixel (Square.to_frame)."""
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)
    square = square_around((30, 20, 90, 100), 1.25)  # side 100, partly outside the image
    region = _upright(square)
    np.testing.assert_array_equal(region.crop(image, square.side), crop_square(image, square, square.side))
    crop_xy = np.array([[0.0, 0.0], [50.0, 50.0], [12.5, 87.25], [100.0, 100.0]])
    np.testing.assert_allclose(region.to_frame(crop_xy, square.side),
                               square.to_frame(crop_xy[:, 0] / square.side, crop_xy[:, 1] / square.side), atol=1e-9)


def test_a_region_turned_a_quarter_puts_the_body_axis_up_in_the_crop():
    """Up in the frame's +x: a mark right of the centre lands above the crop's centre, a mark below
    the centre lands right of it (hand-worked), and the crop's coordinates map back to the marks."""
    image = np.zeros((200, 200, 3), np.uint8)
    centre, side, size = np.array([100.0, 100.0]), 81.0, 81  # odd: the crop's centre is a pixel centre
    marks = {"right": (130, 100), "below": (100, 120)}
    for x, y in marks.values():
        image[y, x] = 255
    region = TurnedSquare(tuple(centre), side, (1.0, 0.0))
    crop = region.crop(image, size)[..., 0]
    found = {}
    for name, (x, y) in marks.items():
        want = np.array([x, y]) - centre  # frame offset; crop x = (offset . (0, 1)), crop y = -(offset . (1, 0))
        cx, cy = size / 2 - 0.5 + want[1], size / 2 - 0.5 - want[0]
        assert crop[int(round(cy)), int(round(cx))] == 255, name
        found[name] = region.to_frame(np.array([[cx + 0.5, cy + 0.5]]), size)[0]
    for name, (x, y) in marks.items():
        np.testing.assert_allclose(found[name], (x, y), atol=1e-9)
    assert crop.sum() == 2 * 255  # nothing else lit: a pure quarter turn, same scale


def test_the_aligned_square_of_two_alignment_points():
    """Side = 2 x the circle's radius x the ROI scale; up from the centre to the rim; none when degenerate."""
    region = aligned_square(np.array([10.0, 50.0]), np.array([10.0 + 30.0, 50.0 - 40.0]))
    assert region.centre == (10.0, 50.0)
    assert region.side == pytest.approx(2 * 50.0 * ROI_SCALE)
    np.testing.assert_allclose(region.up, (0.6, -0.8))
    assert aligned_square(np.array([5.0, 5.0]), np.array([5.0, 5.0 + MIN_RADIUS_PX - 0.5])) is None
    assert aligned_square(np.array([5.0, np.nan]), np.array([5.0, 50.0])) is None


def _region(x: float, y: float, side: float = 200.0) -> TurnedSquare:
    return TurnedSquare((x, y), side, (0.0, -1.0))


def test_a_frame_crops_the_regions_of_the_frame_before_it_only():
    """Regions found on a frame serve the next frame, not the frame itself (its other people, a second
    pass) nor the frame after the next: a person not found on a frame has no region on the one after."""
    memory, box = RegionMemory(), np.array([40.0, 20.0, 160.0, 180.0])
    memory.begin(0)
    memory.add(_region(100, 100))
    assert memory.region_for(box, 200.0) is None  # found on this frame
    memory.begin(0)  # the same frame again (its next person)
    assert memory.region_for(box, 200.0) is None
    memory.begin(1)
    assert memory.region_for(box, 200.0) == _region(100, 100)
    memory.begin(2)  # nothing was found on frame 1
    assert memory.region_for(box, 200.0) is None
    assert memory.region_for(None, 200.0) is None


def test_several_people_each_crop_the_region_centred_nearest_their_box():
    """Two people's regions both centred in one box (people overlapping): the nearer to the box's centre
    serves it, whichever was found first; a box of another size or elsewhere gets none; without a box,
    the newest."""
    memory = RegionMemory()
    memory.begin(0)
    mine, other = _region(100, 100), _region(150, 100)
    memory.add(mine)
    memory.add(other)
    memory.begin(1)
    box = np.array([40.0, 20.0, 160.0, 180.0])  # both centres inside; its centre (100, 100)
    assert memory.region_for(box, 200.0) is mine
    assert memory.region_for(np.array([95.0, 95.0, 105.0, 105.0]), 12.5) is None  # mine centred in it, 16x larger
    assert memory.region_for(np.array([95.0, 95.0, 105.0, 105.0]), 100.0) is mine  # within 0.5-3x
    assert memory.region_for(np.array([200.0, 20.0, 300.0, 180.0]), 200.0) is None
    assert memory.region_for(None, 200.0) is other


def test_a_discarded_or_cleared_region_serves_no_frame():
    memory = RegionMemory()
    memory.begin(0)
    kept, dropped = _region(100, 100), _region(400, 100)
    memory.add(kept)
    memory.add(dropped)
    memory.discard(dropped)
    memory.discard(None)
    memory.begin(1)
    assert memory.last == (kept,)
    memory.clear()
    assert memory.last == () and memory.region_for(None, 200.0) is None


def test_a_recording_that_starts_over_crops_no_region_of_its_end():
    """A smaller frame index (a loop back to frame 0, a camera reopened) forgets the last frame's
    regions; a dropped region serves no frame; a frame given again keeps at most MAX_REGIONS."""
    memory, box = RegionMemory(), np.array([40.0, 20.0, 160.0, 180.0])
    memory.begin(41)
    memory.add(_region(100, 100))
    memory.begin(0)
    assert memory.last == () and memory.region_for(box, 200.0) is None
    memory.add(_region(100, 100))
    memory.begin(1)
    memory.drop(memory.region_for(box, 200.0))
    memory.drop(None)
    assert memory.last == ()
    for k in range(MAX_REGIONS + 5):
        memory.add(_region(100 + k, 100))
    memory.begin(2)
    assert len(memory.last) == MAX_REGIONS and memory.last[0] == _region(100 + MAX_REGIONS + 4, 100)
