"""Shaded depth images against hand-computed Lambert shading of planes."""

from __future__ import annotations

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.sources.depth_shading import AMBIENT, LIGHT, shaded_normals

CAMERA = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)


def _plane_depth(normal: np.ndarray, distance: float) -> np.ndarray:
    """Depth (H, W) of the plane n·p = -distance seen through CAMERA (n faces the camera)."""
    u, v = np.meshgrid(np.arange(CAMERA.width), np.arange(CAMERA.height))
    rays = np.stack([(u - CAMERA.cx) / CAMERA.fx, (v - CAMERA.cy) / CAMERA.fy, np.ones_like(u, float)], axis=-1)
    return (-distance / (rays @ normal)).astype(np.float32)


def _expected(normal: np.ndarray) -> int:
    return int(round(255 * (AMBIENT + (1 - AMBIENT) * max(0.0, float(normal @ LIGHT)))))


def test_planes_are_lit_by_lambert_from_the_light_direction():
    for normal in (np.array([0.0, 0.0, -1.0]), np.array([0.5, 0.0, -1.0]), np.array([-0.3, -0.4, -1.0])):
        normal = normal / np.linalg.norm(normal)
        image = shaded_normals(_plane_depth(normal, 2.0), CAMERA)
        assert image.shape == (48, 64, 3) and image.dtype == np.uint8
        assert np.all(image[..., 0] == image[..., 1])
        inner = image[2:-2, 2:-2, 0].astype(int)
        assert np.all(np.abs(inner - _expected(normal)) <= 1), (normal, np.unique(inner))


def test_missing_depth_is_black_and_silhouettes_do_not_smear():
    depth = np.full((48, 64), 3.0, np.float32)
    depth[:, :20] = 0.0  # no depth
    depth[10:30, 30:50] = 1.5  # a box in front of the wall
    image = shaded_normals(depth, CAMERA)[..., 0]
    assert np.all(image[:, :20] == 0)
    flat = _expected(np.array([0.0, 0.0, -1.0]))
    # both sides of the box's edge keep the flat shading (one-sided differences across the step)
    assert np.all(np.abs(image[10:30, 30:50].astype(int) - flat) <= 1)
    assert np.all(np.abs(image[35:, 25:].astype(int) - flat) <= 1)


def test_point_map_back_projects_pixels():
    depth = np.zeros((48, 64), np.float32)
    depth[23, 31] = 2.0
    points = CAMERA.point_map(depth)
    np.testing.assert_allclose(points[23, 31], [2.0 * (31 - 31.5) / 60, 2.0 * (23 - 23.5) / 60, 2.0])
    assert np.isnan(points[0, 0]).all()
