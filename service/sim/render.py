"""Ground-truth rendering of a posed body in a simple room with Open3D's RaycastingScene.

This renderer is deliberately independent of the OpenCL scorer's rasterizer, so each
checks the other. Everything is in the camera frame (OpenCV axes, metres); depth is the
z coordinate of the first hit (0 = no hit), colour a Lambert-shaded RGB image.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics

BODY_ALBEDO = np.array([0.87, 0.68, 0.55])
FLOOR_ALBEDO = (np.array([0.55, 0.50, 0.45]), np.array([0.42, 0.38, 0.34]))
WALL_ALBEDO = np.array([0.72, 0.75, 0.80])
AMBIENT = 0.3


@dataclass(frozen=True)
class Room:
    """A floor and a back wall, as triangle meshes in the camera frame.

    floor_point / floor_normal: a point on the floor plane and its upward unit normal;
    wall_point / wall_normal: the same for the wall facing the camera. ``checker`` is the
    floor's checkerboard square size in metres (0 = plain).
    """

    floor_point: np.ndarray
    floor_normal: np.ndarray
    wall_point: np.ndarray
    wall_normal: np.ndarray
    checker: float = 0.5
    extent: float = 30.0

    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(vertices (4, 3), triangles (2, 3)) for the floor and the wall."""
        out = []
        for point, normal in ((self.floor_point, self.floor_normal), (self.wall_point, self.wall_normal)):
            n = normal / np.linalg.norm(normal)
            a = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
            a /= np.linalg.norm(a)
            b = np.cross(n, a)
            e = self.extent
            verts = np.stack([point + e * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
            out.append((verts, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)))
        return out


class Renderer:
    """Casts one ray per pixel of ``intrinsics`` at a body mesh plus an optional room."""

    def __init__(self, intrinsics: Intrinsics):
        import open3d as o3d

        self._o3d = o3d
        self.intrinsics = intrinsics
        # Open3D aims the ray of pixel (i, j) at (i + 0.5, j + 0.5); ours passes through the
        # pixel centre (i, j) (OpenCV, as Intrinsics.project), hence the half-pixel shift.
        k = intrinsics.matrix.copy()
        k[0, 2] += 0.5
        k[1, 2] += 0.5
        rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
            o3d.core.Tensor(k), o3d.core.Tensor(np.eye(4)), intrinsics.width, intrinsics.height)
        self._rays = rays
        self._dirs = rays.numpy()[..., 3:]  # (H, W, 3) with z = 1, so the hit distance t is the depth z
        self._view = -self._dirs / np.linalg.norm(self._dirs, axis=-1, keepdims=True)

    def render(self, vertices: np.ndarray, triangles: np.ndarray, room: Room | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Depth (H, W) float32 m (0 = nothing hit), colour (H, W, 3) uint8 RGB and the
        body mask (H, W) bool, for one posed mesh: vertices (V, 3) m, triangles (F, 3)."""
        o3d = self._o3d
        scene = o3d.t.geometry.RaycastingScene()
        body_id = scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
                                      o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)))
        ids = [body_id]
        if room is not None:
            for verts, tris in room.meshes():
                ids.append(scene.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris)))
        hit = scene.cast_rays(self._rays)
        t = hit["t_hit"].numpy()
        geom = hit["geometry_ids"].numpy()
        normals = hit["primitive_normals"].numpy()
        valid = np.isfinite(t)
        depth = np.where(valid, t, 0.0).astype(np.float32)
        body = valid & (geom == body_id)

        shade = AMBIENT + (1 - AMBIENT) * np.abs(np.sum(normals * self._view, axis=-1))
        albedo = np.zeros(depth.shape + (3,))
        albedo[body] = BODY_ALBEDO
        if room is not None:
            floor = valid & (geom == ids[1])
            wall = valid & (geom == ids[2])
            albedo[wall] = WALL_ALBEDO
            if np.any(floor):
                pts = self._dirs[floor] * t[floor, None]
                n = room.floor_normal / np.linalg.norm(room.floor_normal)
                a = np.cross(n, [1.0, 0, 0])
                a /= np.linalg.norm(a)
                b = np.cross(n, a)
                rel = pts - room.floor_point
                if room.checker > 0:
                    parity = (np.floor(rel @ a / room.checker) + np.floor(rel @ b / room.checker)) % 2
                else:
                    parity = np.zeros(len(rel))
                albedo[floor] = np.where(parity[:, None] > 0, FLOOR_ALBEDO[1], FLOOR_ALBEDO[0])
        colour = np.clip(albedo * shade[..., None] * 255.0, 0, 255).astype(np.uint8)
        return depth, colour, body
