"""Ground-truth rendering of a posed body in a simple room with Open3D's RaycastingScene.

This renderer is deliberately independent of the OpenCL scorer's rasterizer, so each
checks the other. Everything is in the camera frame (OpenCV axes, metres); depth is the
z coordinate of the first hit (0 = no hit), colour a Lambert-shaded RGB image. Several
people are cast together so they occlude each other; a label image says whose surface
each pixel shows. The room may hold props (boxes: a stool, a table, :mod:`swarmpose.sim.props`),
cast with everything else, in their own colour, labelled as no person.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import check_shape
from swarmpose.core.open3d_import import open3d

BODY_ALBEDO = np.array([0.87, 0.68, 0.55])
PERSON_ALBEDOS = (
    BODY_ALBEDO,                    # person 1: the single-person colour
    np.array([0.25, 0.42, 0.78]),   # blue
    np.array([0.32, 0.64, 0.30]),   # green
    np.array([0.80, 0.28, 0.26]),   # red
    np.array([0.58, 0.36, 0.72]),   # violet
    np.array([0.88, 0.78, 0.25]),   # yellow
)
"""Clothing albedos (RGB 0..1) of people 1, 2, ... in a scene, distinct so a 2D network can
tell them apart; the palette repeats after its last colour."""
FLOOR_ALBEDO = (np.array([0.55, 0.50, 0.45]), np.array([0.42, 0.38, 0.34]))
WALL_ALBEDO = np.array([0.72, 0.75, 0.80])
AMBIENT = 0.3


@dataclass(frozen=True)
class Solid:
    """A static object of the room (a prop): vertices (V, 3) m in the camera frame, triangles
    (F, 3) and its albedo (3,) RGB 0..1."""

    vertices: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray


@dataclass(frozen=True)
class Room:
    """A floor and a back wall, as triangle meshes in the camera frame, and the props in it.

    floor_point / floor_normal: a point on the floor plane and its upward unit normal;
    wall_point / wall_normal: the same for the wall facing the camera. ``checker`` is the
    floor's checkerboard square size in metres (0 = plain). ``props``: solids standing in the
    room (labelled -1, -2, ... in :meth:`Renderer.render_people`'s label image).
    """

    floor_point: np.ndarray
    floor_normal: np.ndarray
    wall_point: np.ndarray
    wall_normal: np.ndarray
    checker: float = 0.5
    extent: float = 30.0
    props: tuple[Solid, ...] = ()

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


def person_albedo(index: int) -> np.ndarray:
    """The albedo (3,) of the person at 0-based ``index`` of a scene (see :data:`PERSON_ALBEDOS`)."""
    return PERSON_ALBEDOS[index % len(PERSON_ALBEDOS)]


class Renderer:
    """Casts one ray per pixel of ``intrinsics`` at one or more body meshes plus an optional room."""

    def __init__(self, intrinsics: Intrinsics):
        o3d = open3d()

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
        depth, colour, labels = self.render_people([(vertices, triangles)], room)
        return depth, colour, labels == 1

    def render_people(self, meshes: Sequence[tuple[np.ndarray, np.ndarray]], room: Room | None = None,
                      albedos: Sequence[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Several posed meshes (and the room) in one ray cast, so they occlude each other.

        meshes: per person (vertices (V, 3) m, triangles (F, 3)); albedos: per person an RGB
        albedo in 0..1, (3,) for the whole body or (F, 3) per triangle (clothes,
        :mod:`swarmpose.sim.clothing`); default :func:`person_albedo`. Returns depth (H, W) float32 m
        (0 = nothing hit), colour (H, W, 3) uint8 RGB and labels (H, W) int32: k where person
        k (1-based, in ``meshes`` order) is the first surface hit, -m where the room's prop m
        (1-based, in ``room.props`` order) is, 0 for the floor, the wall or nothing.
        """
        o3d = self._o3d
        scene = o3d.t.geometry.RaycastingScene()
        person_ids = [scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(v, dtype=np.float32)),
                                          o3d.core.Tensor(np.ascontiguousarray(f, dtype=np.uint32)))
                      for v, f in meshes]
        ids = []
        if room is not None:
            for verts, tris in room.meshes() + [(p.vertices, p.triangles) for p in room.props]:
                ids.append(scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(verts, dtype=np.float32)),
                                               o3d.core.Tensor(np.ascontiguousarray(tris, dtype=np.uint32))))
        hit = scene.cast_rays(self._rays)
        t = hit["t_hit"].numpy()
        geom = hit["geometry_ids"].numpy()
        normals = hit["primitive_normals"].numpy()
        valid = np.isfinite(t)
        depth = np.where(valid, t, 0.0).astype(np.float32)
        labels = np.zeros(depth.shape, dtype=np.int32)

        shade = AMBIENT + (1 - AMBIENT) * np.abs(np.sum(normals * self._view, axis=-1))
        albedo = np.zeros(depth.shape + (3,))
        triangle = hit["primitive_ids"].numpy()
        for k, geometry in enumerate(person_ids):
            body = valid & (geom == geometry)
            labels[body] = k + 1
            paint = person_albedo(k) if albedos is None else np.asarray(albedos[k], float)
            if paint.ndim == 2:  # one per triangle
                check_shape(f"person {k + 1}'s albedos (one per triangle)", paint, (len(meshes[k][1]), 3))
                paint = paint[triangle[body]]
            albedo[body] = paint
        if room is not None:
            floor = valid & (geom == ids[0])
            wall = valid & (geom == ids[1])
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
            for m, prop in enumerate(room.props, 1):
                solid = valid & (geom == ids[1 + m])
                labels[solid] = -m
                albedo[solid] = prop.albedo
        colour = np.clip(albedo * shade[..., None] * 255.0, 0, 255).astype(np.uint8)
        return depth, colour, labels

    def silhouette(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """(H, W) bool: the pixels one mesh (vertices (V, 3) m, triangles (F, 3)) covers when
        nothing else is in the scene."""
        o3d = self._o3d
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
                            o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)))
        return np.isfinite(scene.cast_rays(self._rays)["t_hit"].numpy())
