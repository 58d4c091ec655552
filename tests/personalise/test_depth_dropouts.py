"""The shape fit's dropout fill, against hand-counted neighbourhoods on step edges."""

from __future__ import annotations

import numpy as np

from swarmpose.personalise.depth_dropouts import fill_dropouts

PERSON_M, WALL_M = 3.0, 4.5


def _person_before_a_wall(wall: float = WALL_M) -> np.ndarray:
    """(60, 80) depth: a 30 x 20 px rectangle at 3 m on a wall (0: background removed)."""
    depth = np.full((60, 80), wall, np.float32)
    depth[15:45, 30:50] = PERSON_M
    return depth


def _outline(mask: np.ndarray) -> np.ndarray:
    """Pixels of ``mask`` with a 4-neighbour outside it: the one-pixel ring along its edge."""
    pad = np.pad(mask, 1)
    inner = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
    return mask & ~inner


def test_edge_dropouts_take_the_depth_of_their_own_side():
    """60 % of the pixels on both sides of the person's outline dropped, as the simulated Kinect
    drops them: at least 85 % of each side's dropouts get their own side's depth back, almost
    none the other side's, none a depth between the two, and the person's area stays within 2 %
    of the truth's (the fill neither grows nor shrinks the outline)."""
    clean = _person_before_a_wall()
    person = clean == PERSON_M
    beside = _outline(np.pad(~person, 1, constant_values=True))[1:-1, 1:-1] & ~person  # the wall's ring
    rng = np.random.default_rng(0)
    lost = (_outline(person) | beside) & (rng.random(clean.shape) < 0.6)
    filled = fill_dropouts(np.where(lost, 0.0, clean))
    for side in (person, ~person):
        judged = lost & side
        assert judged.sum() > 40
        assert np.mean(filled[judged] == clean[judged]) >= 0.85
    assert np.isin(filled[lost], (0.0, PERSON_M, WALL_M)).all()
    assert np.mean((filled[lost] > 0) & (filled[lost] != clean[lost])) <= 0.02
    assert abs(int((filled == PERSON_M).sum()) - int(person.sum())) <= 0.02 * person.sum()


def test_a_person_on_a_removed_background_does_not_grow():
    """Background removed (0): a pixel outside a straight edge has 3 valid neighbours, one
    outside a corner 1, fewer than MIN_VALID (4), so nothing outside the person is filled; a
    single lost pixel inside has 8 and takes the person's depth."""
    clean = _person_before_a_wall(wall=0.0)
    holed = clean.copy()
    holed[30, 40] = 0.0
    filled = fill_dropouts(holed)
    np.testing.assert_array_equal(filled, clean)


def test_a_wide_hole_fills_only_its_corners_and_nothing_else_changes():
    """A 5 x 5 hole in the person, by hand: each corner of it has 5 valid neighbours (3 above or
    below, 2 beside) and is filled; its other 12 ring pixels have 3, fewer than MIN_VALID, and its
    3 x 3 inside none, so one pass leaves them empty; valid pixels never change."""
    clean = _person_before_a_wall()
    holed = clean.copy()
    holed[25:30, 37:42] = 0.0
    filled = fill_dropouts(holed)
    expected = holed.copy()
    for r, c in ((25, 37), (25, 41), (29, 37), (29, 41)):
        expected[r, c] = PERSON_M
    np.testing.assert_array_equal(filled, expected)


def test_on_a_removed_background_a_one_pixel_gap_beside_the_torso_is_closed():
    """The documented limit: an arm one pixel from the torso (2 cm nearer), background removed.
    Each gap pixel has 6 valid neighbours (3 on each side), more than half of them within 10 cm
    of their median, so the gap is filled and the silhouette closes it; nothing else changes."""
    depth = np.zeros((40, 30), np.float32)
    depth[5:35, 5:15] = PERSON_M  # the torso
    depth[5:35, 16:19] = PERSON_M - 0.02  # the arm, one pixel beside it
    filled = fill_dropouts(depth)
    assert np.all(filled[6:34, 15] > 0)
    outside = np.ones_like(depth, bool)
    outside[5:35, 15] = False
    np.testing.assert_array_equal(filled[outside], depth[outside])
