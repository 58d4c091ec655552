"""Signed-distance primitives of the built-in body and their meshing.

Parts are an ellipsoid, a tapered capsule ("cone"), a rounded box (:class:`Part`) and a
lofted elliptical torso (:class:`Torso`); :func:`sample_field` smooth-unions them on a
regular grid and :func:`mesh_field` turns the zero level set into an outward-oriented,
decimated triangle mesh. Everything is in metres; distances are negative inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.core.open3d_import import open3d


def smooth_min(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance fields, blend radius ``k``."""
    h = np.maximum(k - np.abs(a - b), 0.0) / k
    return np.minimum(a, b) - 0.25 * k * h * h


@dataclass(frozen=True)
class Part:
    """A primitive with its bone. ``kind``: ellipsoid, cone or box; ``frame`` rows = local axes."""

    bone: str
    kind: str
    centre: np.ndarray  # (3,) ellipsoid/box centre, cone start
    size: np.ndarray  # ellipsoid/box half-extents (3,), cone (end x, y, z, r0, r1)
    frame: np.ndarray | None = None  # (3, 3) rows = local axes, for rotated boxes/ellipsoids
    rounding: float = 0.0

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance estimate (N,) m of points (N, 3) m; negative inside."""
        q = p - self.centre
        if self.frame is not None:
            q = q @ self.frame.T
        if self.kind == "ellipsoid":
            r = self.size
            k0 = np.linalg.norm(q / r, axis=1)
            k1 = np.maximum(np.linalg.norm(q / (r * r), axis=1), 1e-12)
            return k0 * (k0 - 1.0) / k1
        if self.kind == "box":
            d = np.abs(q) - (self.size - self.rounding)
            outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
            return outside + np.minimum(d.max(axis=1), 0.0) - self.rounding
        if self.kind == "cone":  # capsule whose radius varies linearly from r0 to r1
            axis, r0, r1 = self.size[:3] - self.centre, self.size[3], self.size[4]
            t = np.clip(q @ axis / (axis @ axis), 0.0, 1.0)
            return np.linalg.norm(q - t[:, None] * axis, axis=1) - (r0 + (r1 - r0) * t)
        raise ValueError(self.kind)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo, hi) (3,) each, m, containing the part."""
        if self.kind == "cone":
            end, r = self.size[:3], max(self.size[3], self.size[4])
            return np.minimum(self.centre, end) - r, np.maximum(self.centre, end) + r
        reach = np.linalg.norm(self.size) if self.frame is not None else self.size
        return self.centre - reach, self.centre + reach


@dataclass(frozen=True)
class Torso:
    """Lofted torso: elliptical sections (half-width a, half-depth b, centre z) along y."""

    keys: np.ndarray  # (K, 4) y, a, b, c

    def profile(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Half-width, half-depth and centre z (N,) each, m, at heights ``y`` (N,) m (clamped to the keys)."""
        from scipy.interpolate import PchipInterpolator

        yy = np.clip(y, self.keys[0, 0], self.keys[-1, 0])
        return tuple(PchipInterpolator(self.keys[:, 0], self.keys[:, i])(yy) for i in (1, 2, 3))

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """First-order distance estimate (N,) to the loft surface, capped at both ends."""
        a, b, c = self.profile(p[:, 1])
        u, v = p[:, 0] / a, (p[:, 2] - c) / b
        k = np.hypot(u, v)
        grad = np.maximum(np.hypot(u / a, v / b), 1e-12) / np.maximum(k, 1e-12)
        grad = np.where(k < 1e-9, 1.0 / np.maximum(a, b), grad)
        radial = (k - 1.0) / grad
        caps = np.maximum(self.keys[0, 0] - p[:, 1], p[:, 1] - self.keys[-1, 0])
        return np.maximum(radial, caps)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        ks = self.keys
        return (np.array([-ks[:, 1].max(), ks[0, 0], (ks[:, 3] - ks[:, 2]).min()]),
                np.array([ks[:, 1].max(), ks[-1, 0], (ks[:, 3] + ks[:, 2]).max()]))


def sample_field(parts: tuple, blend: float, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample the smooth union of ``parts`` on a grid: returns (values (nx, ny, nz), origin (3,)), m.

    ``blend``: smooth-union radius, m; ``resolution``: grid step, m. The field is cut flat
    at the floor y = 0 (flat soles).
    """
    k = blend
    lo = np.min([p.bounds()[0] for p in parts], axis=0) - 3 * resolution - k
    hi = np.max([p.bounds()[1] for p in parts], axis=0) + 3 * resolution + k
    lo[1] = -3 * resolution
    lo = np.floor(lo / resolution) * resolution
    n = np.ceil((hi - lo) / resolution).astype(int) + 1
    axes = [lo[i] + resolution * np.arange(n[i]) for i in range(3)]
    far = 1.0
    values = np.full(tuple(n), far)
    for part in parts:
        plo, phi = part.bounds()
        i0 = np.clip(np.floor((plo - k - 2 * resolution - lo) / resolution).astype(int), 0, n - 1)
        i1 = np.clip(np.ceil((phi + k + 2 * resolution - lo) / resolution).astype(int) + 1, 1, n)
        block = tuple(slice(a, b) for a, b in zip(i0, i1, strict=True))
        grid = np.stack(np.meshgrid(*(ax[sl] for ax, sl in zip(axes, block, strict=True)), indexing="ij"), -1)
        d = part.sdf(grid.reshape(-1, 3)).reshape(grid.shape[:3])
        values[block] = smooth_min(values[block], np.minimum(d, far), k)
    values = np.maximum(values, -axes[1][None, :, None])  # flat soles: cut at the floor y = 0
    return values, lo


def mesh_field(values: np.ndarray, origin: np.ndarray, resolution: float,
               target_triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes + outward orientation + quadric decimation -> (V, 3) m, (F, 3) int32.

    ``values`` (nx, ny, nz) and ``origin`` (3,) m as from :func:`sample_field`, sampled
    every ``resolution`` m; meshes above ``target_triangles`` triangles are decimated to it.
    """
    o3d = open3d()
    from skimage.measure import marching_cubes

    verts, faces, _, _ = marching_cubes(values, 0.0, spacing=(resolution,) * 3, allow_degenerate=False)
    verts = verts + origin
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts), o3d.utility.Vector3iVector(faces))
    if len(faces) > target_triangles:
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=target_triangles)
    mesh.remove_degenerate_triangles()
    mesh.remove_unreferenced_vertices()
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.triangles, dtype=np.int32)
    if signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume (m^3) enclosed by triangles; > 0 when they wind counter-clockwise outside."""
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals (V, 3) of triangles (F, 3) over vertices (V, 3); +Y for
    vertices in no triangle. They point the way the triangles wind (counter-clockwise: out)."""
    tri = vertices[triangles]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 1e-20, normals / np.where(length > 0, length, 1.0), [0.0, 1.0, 0.0])
