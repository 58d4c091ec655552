"""Lifts of the joints the track's own body hides, taken out of the 3D joint term.

A joint's lift J^e is the depth of the surface in front of its keypoint pushed back by the joint's
radius (:mod:`swarmpose.tracking.lift`). For a joint that another part of the body hides (the far
arm of a person seen from the side, behind the torso) that surface is the occluder's, and the
symmetric 3D term pulls the joint towards the camera, by as much as the occluder is thick. Were
the previous solution alone to decide which joints are hidden, a track that wrongly held an arm
behind the torso would keep it there, so a lift leaves the 3D term only when two tests agree:

1. **the previous solution hides the joint**: along the camera ray through the joint, the body's
   own surface lies more than :data:`HIDDEN_M` in front of it (a visible limb joint lies its
   radius, 2.5-4.5 cm, behind its surface);
2. **the observation agrees with that occluder**: the observed surface at the keypoint lies within
   :data:`EXPLAINED_M` of the previous solution's surface on the keypoint's ray. An arm the track
   wrongly holds behind the torso shows in the depth in front of the model's torso, fails this
   test, and keeps its lift to pull it out.

The 2D term keeps the keypoint. Only the limbs' middle and end joints (elbows, wrists, knees,
ankles) are tested: shoulders and hips are placed by the torso.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.open3d_import import open3d
from swarmpose.tracking.body_scene import body_scene
from swarmpose.tracking.lift import JOINT_RADIUS
from swarmpose.tracking.objective import JointTargets

LIMB_JOINTS = frozenset(f"{side}_{joint}" for side in ("left", "right")
                        for joint in ("elbow", "wrist", "knee", "ankle"))
"""The joints whose lifts are tested."""
HIDDEN_M = 0.10
"""A joint this far (m) behind its own body's surface on its camera ray is hidden."""
EXPLAINED_M = 0.05
"""The observed surface at a keypoint within this (m) of the model's occluder: the lift measured it."""


def hidden_lifts(body: SkinnedBody, pose: np.ndarray, targets: JointTargets, intrinsics: Intrinsics,
                 scene=None) -> np.ndarray:
    """(n,) bool over ``targets``: the lifts that measured the occluder of a joint the previous
    solution ``pose`` (36,) hides (see the module docstring). Camera frame, m. scene: the posed
    body's :func:`~swarmpose.tracking.body_scene.body_scene` when the caller has it (None: built
    here if a joint is to be tested)."""
    out = np.zeros(targets.count, bool)
    tested = [i for i, name in enumerate(targets.names)
              if name in LIMB_JOINTS and np.all(np.isfinite(targets.xyz[i]))]
    if not tested:
        return out
    o3d = open3d()

    scene = body_scene(body, pose) if scene is None else scene
    names = [targets.names[i] for i in tested]
    joints = body.posed_points(pose[None], names)[0]  # (k, 3)
    joint_range = np.linalg.norm(joints, axis=1)
    xy = targets.xy[tested]
    keys = np.stack([(xy[:, 0] - intrinsics.cx) / intrinsics.fx, (xy[:, 1] - intrinsics.cy) / intrinsics.fy,
                     np.ones(len(xy))], axis=1)
    keys /= np.linalg.norm(keys, axis=1, keepdims=True)
    directions = np.concatenate([joints / joint_range[:, None], keys])
    rays = np.concatenate([np.zeros_like(directions), directions], axis=1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    own_surface, occluder = hit[:len(tested)], hit[len(tested):]
    observed = np.linalg.norm(targets.xyz[tested], axis=1) - np.array([JOINT_RADIUS.get(n, 0.0) for n in names])
    with np.errstate(invalid="ignore"):
        hidden = joint_range - own_surface > HIDDEN_M
        explained = np.abs(observed - occluder) < EXPLAINED_M
    out[tested] = hidden & explained
    return out


def without_hidden_lifts(body: SkinnedBody, pose: np.ndarray, targets: JointTargets,
                         intrinsics: Intrinsics, scene=None) -> JointTargets:
    """``targets`` with the lifts :func:`hidden_lifts` finds set to NaN (out of the 3D term)."""
    hidden = hidden_lifts(body, pose, targets, intrinsics, scene)
    if not hidden.any():
        return targets
    xyz = targets.xyz.copy()
    xyz[hidden] = np.nan
    return replace(targets, xyz=xyz)
