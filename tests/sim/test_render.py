"""The ground-truth renderer against hand-computed pinhole geometry."""

from __future__ import annotations

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.sim.render import Renderer


def test_pixel_centres_follow_the_opencv_convention():
    """An edge projecting to u = 320.25 covers pixel columns whose centre u <= 320 only."""
    intr = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    z = 2.0
    x_edge = (320.25 - 319.5) * z / 525.0
    y_edge = (240.25 - 239.5) * z / 525.0
    # A square at depth z covering x < x_edge and y < y_edge (camera frame, y down).
    verts = np.array([[-5, -5, z], [x_edge, -5, z], [x_edge, y_edge, z], [-5, y_edge, z]], dtype=np.float64)
    depth, colour, mask = Renderer(intr).render(verts, np.array([[0, 1, 2], [0, 2, 3]]))
    assert mask[100, 320] and not mask[100, 321]
    assert mask[240, 100] and not mask[241, 100]
    np.testing.assert_allclose(depth[mask], z, atol=1e-5)
    assert np.all(depth[~mask] == 0) and colour.shape == (480, 640, 3)


def test_depth_is_z_not_ray_length():
    intr = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    # A plane z = 1.5 seen at the image corner, where the ray is long: depth must still be 1.5.
    verts = np.array([[-10, -10, 1.5], [10, -10, 1.5], [10, 10, 1.5], [-10, 10, 1.5]])
    depth, _, _ = Renderer(intr).render(verts, np.array([[0, 1, 2], [0, 2, 3]]))
    np.testing.assert_allclose(depth, 1.5, atol=1e-5)
