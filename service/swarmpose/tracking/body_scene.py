"""The last solution's body as an Open3D ray-casting scene, built once a frame for the rules that
ask it where its surface is (:mod:`~swarmpose.tracking.hidden_lifts`: along camera rays;
:mod:`~swarmpose.tracking.arm_proposals`: how far observed points lie from it)."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.open3d_import import open3d


def body_scene(body: SkinnedBody, pose: np.ndarray):
    """An ``open3d.t.geometry.RaycastingScene`` holding ``body``'s mesh posed at ``pose`` (36,),
    camera frame, m (float32, as Open3D keeps it)."""
    o3d = open3d()

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(body.pose(np.asarray(pose, float)[None])[0], np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(body.triangles, np.uint32)))
    return scene
