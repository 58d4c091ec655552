"""Registering a depth image to another camera: reprojection with lens distortion and a z-buffer.

For every depth pixel (u, v) with depth d (the z coordinate in the depth camera, metres):
the undistorted ray (x, y) = ``cv2.undistortPoints`` of the pixel centre (computed once per
pixel), the point X = d (x, y, 1), moved into the target camera X' = R X + t, projected with
the target's lens model (:func:`project`: OpenCV's rational model, the equations of
``cv2.projectPoints`` in numpy). Each depth pixel covers its footprint in the target image
(where its neighbours at the same depth project, through both lenses), so a
lower-resolution depth image leaves no holes on a smooth surface; where points compete for
a pixel the nearest wins (z-buffer). The output is z' (metres, 0 = none) on the
target's pixel grid: depth registered to the target camera, as the Azure Kinect SDK's
``transformation_depth_image_to_color_camera`` produces it.
"""

from __future__ import annotations

import numpy as np

from swarmpose.sources.k4a_calibration import CameraModel

UNDISTORT_TOLERANCE_PX = 0.05


class DepthRegistration:
    """Reprojects (H_d, W_d) depth images of camera ``src`` onto the (H_t, W_t) grid of camera ``dst``.

    ``src.R``, ``src.t`` and ``dst.R``, ``dst.t`` are both relative to one reference camera
    (x_cam = R x_ref + t); the depth→target transform is derived from them.
    """

    def __init__(self, src: CameraModel, dst: CameraModel):
        import cv2

        self.src, self.dst = src, dst
        h, w = src.height, src.width
        grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1)
        pix = grid.reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
        rays = cv2.undistortPoints(pix, src.K, src.dist, None, None, None, criteria).reshape(h, w, 2)
        back = cv2.projectPoints(np.concatenate([rays.reshape(-1, 2), np.ones((h * w, 1))], 1),
                                 np.zeros(3), np.zeros(3), src.K, src.dist)[0].reshape(h, w, 2)
        radius = np.hypot(rays[..., 0], rays[..., 1])
        self.valid = (np.abs(back - grid).max(-1) < UNDISTORT_TOLERANCE_PX) & (radius <= src.max_radius)
        self.rays = rays.astype(np.float64)
        # footprint of one depth pixel in normalised coordinates (spacing of neighbouring rays)
        self.step_x = np.abs(np.gradient(rays[..., 0], axis=1))
        self.step_y = np.abs(np.gradient(rays[..., 1], axis=0))
        # depth -> target: x_t = R_t R_s^T (x_s - t_s) + t_t
        self.R = dst.R @ src.R.T
        self.t = dst.t - self.R @ src.t

    def points(self, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) depth-camera points (m) of the valid pixels of ``depth`` and their (N,) flat pixel indices."""
        sel = (depth > 0) & self.valid
        z = depth[sel].astype(np.float64)
        xy = self.rays[sel]
        return np.column_stack([xy * z[:, None], z]), np.flatnonzero(sel)

    def __call__(self, depth: np.ndarray, values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Register ``depth`` (H_d, W_d) float metres to the target grid.

        Returns (H_t, W_t) float32 metres (z in the target camera, 0 = none) and, when
        ``values`` (H_d, W_d) is given (e.g. the IR image), those values carried along by the
        same z-buffer (0 where no depth lands).
        """

        dst = self.dst
        pts, flat = self.points(np.asarray(depth))
        out = np.zeros((dst.height, dst.width), np.float32)
        carried = None if values is None else np.zeros((dst.height, dst.width), np.asarray(values).dtype)
        if not len(pts):
            return out, carried
        cam = pts @ self.R.T + self.t
        front = cam[:, 2] > 1e-6
        cam, flat, z_src = cam[front], flat[front], pts[front, 2]
        norm = cam[:, :2] / cam[:, 2:3]
        inside = np.hypot(norm[:, 0], norm[:, 1]) <= dst.max_radius
        cam, flat, z_src = cam[inside], flat[inside], z_src[inside]
        uv = project(cam, dst.K, dst.dist)
        # the footprint: where the neighbouring depth pixels (same depth) land, through both lenses
        a = project(cam + (self.step_x.ravel()[flat] * z_src)[:, None] * self.R[:, 0], dst.K, dst.dist) - uv
        b = project(cam + (self.step_y.ravel()[flat] * z_src)[:, None] * self.R[:, 1], dst.K, dst.dist) - uv
        half_x = (np.abs(a[:, 0]) + np.abs(b[:, 0])) / 2
        half_y = (np.abs(a[:, 1]) + np.abs(b[:, 1])) / 2
        z = cam[:, 2]
        # target pixels j with u - half <= j < u + half, per axis
        x0 = np.ceil(uv[:, 0] - half_x).astype(np.int64)
        y0 = np.ceil(uv[:, 1] - half_y).astype(np.int64)
        nx = np.ceil(uv[:, 0] + half_x).astype(np.int64) - x0
        ny = np.ceil(uv[:, 1] + half_y).astype(np.int64) - y0
        most = int(max(nx.max(), ny.max()))
        rows, cols, depths, sources = [], [], [], []
        for ky in range(most):
            rv = y0 + ky
            ok_v = (ky < ny) & (rv >= 0) & (rv < dst.height)
            for kx in range(most):
                ru = x0 + kx
                idx = np.flatnonzero(ok_v & (kx < nx) & (ru >= 0) & (ru < dst.width))
                rows.append(rv[idx])
                cols.append(ru[idx])
                depths.append(z[idx])
                sources.append(flat[idx])
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        depths, sources = np.concatenate(depths), np.concatenate(sources)
        target = rows * dst.width + cols
        order = np.lexsort((depths, target))  # by pixel, nearest first
        first = np.ones(len(order), bool)
        first[1:] = target[order][1:] != target[order][:-1]
        win = order[first]
        out.ravel()[target[win]] = depths[win]
        if carried is not None:
            carried.ravel()[target[win]] = np.asarray(values).ravel()[sources[win]]
        return out, carried


def project(points: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Camera-frame points (N, 3) -> pixels (N, 2) through OpenCV's rational lens model.

    dist = [k1, k2, p1, p2, k3, k4, k5, k6]; the same equations as ``cv2.projectPoints``
    (which the tests use as the oracle), vectorised in numpy because OpenCV's binding is an
    order of magnitude slower on a few hundred thousand points.
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = np.asarray(dist, dtype=np.float64)
    x = points[:, 0] / points[:, 2]
    y = points[:, 1] / points[:, 2]
    x2, y2, xy = x * x, y * y, x * y
    r2 = x2 + y2
    r4, r6 = r2 * r2, r2 * r2 * r2
    radial = (1 + k1 * r2 + k2 * r4 + k3 * r6) / (1 + k4 * r2 + k5 * r4 + k6 * r6)
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x2)
    yd = y * radial + p1 * (r2 + 2 * y2) + 2 * p2 * xy
    return np.column_stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])
