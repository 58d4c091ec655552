"""Independent references for the OpenCL scorer: Open3D ray casting and a float64 numpy score.

These are the oracles of the tests and the baseline of ``swarmpose bench score``; they
share nothing with the kernels but the formula.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.errors import check_shape
from swarmpose.core.open3d_import import open3d

COUNT_NAMES = ("observed", "rendered", "both", "close")
"""Per-particle counts: observed tile pixels (d_o > 0), rendered pixels (whole tile),
rendered and observed, and rendered and observed with |d_h - d_o| < T."""


def reference_score(rendered: np.ndarray, observed: np.ndarray, threshold: float
                    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The scorer's formula in float64.

    rendered: (P, TH, TW) depth m, 0 = background; observed: (TH, TW) m, 0 = no measurement.
    Returns sums (P,) = sum over observed pixels of min(|d_h - d_o|, T) (an uncovered pixel
    has d_h = 0, so it adds min(d_o, T)), and the counts of :data:`COUNT_NAMES`, each (P,) int64.
    """
    rendered = np.asarray(rendered, dtype=np.float64)
    observed = np.asarray(observed, dtype=np.float64)
    check_shape("rendered tiles", rendered, (None,) + observed.shape)
    obs = observed > 0
    ren = rendered > 0
    diff = np.abs(rendered - observed)
    term = np.where(obs, np.minimum(diff, threshold), 0.0)
    sums = term.reshape(len(rendered), -1).sum(axis=1)

    def count(mask: np.ndarray) -> np.ndarray:
        return mask.reshape(len(rendered), -1).sum(axis=1).astype(np.int64)

    counts = {"observed": count(np.broadcast_to(obs, ren.shape)), "rendered": count(ren),
              "both": count(ren & obs), "close": count(ren & obs & (diff < threshold))}
    return sums, counts


def raycast_tiles(vertices: np.ndarray, triangles: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Depth tiles (P, TH, TW) float32 m (0 = miss) of posed meshes by Open3D ray casting.

    vertices: (P, V, 3) camera-frame m; triangles: (F, 3); rays: (TH, TW, 6) with unit-z
    directions (see :meth:`TileBox.rays`), so the hit distance is the depth. One scene is
    built per mesh, as a per-hypothesis CPU renderer would.
    """
    o3d = open3d()

    check_shape("vertices", vertices, (None, None, 3))
    tris = o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32))
    rays_t = o3d.core.Tensor(np.ascontiguousarray(rays, dtype=np.float32))
    out = np.zeros((len(vertices),) + rays.shape[:2], dtype=np.float32)
    for i, verts in enumerate(vertices):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(verts, dtype=np.float32)), tris)
        t = scene.cast_rays(rays_t)["t_hit"].numpy()
        out[i] = np.where(np.isfinite(t), t, 0.0)
    return out
