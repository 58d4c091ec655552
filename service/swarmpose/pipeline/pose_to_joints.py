"""A published body moved to given joint positions, its pose fitted to them (inverse kinematics).

Both offline refinements of the published poses end here: the centred smoothing
(:mod:`swarmpose.pipeline.centred_smoothing`) with each joint read off its line through time, the
ensemble (:mod:`swarmpose.pipeline.ensemble`) with each joint the mean of several tracks'. The pose
is fitted with :func:`~swarmpose.body.joint_fit.fit_pose_to_points`, so the skeleton keeps the body's
bone lengths and the pose, the joints and a BVH agree.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from swarmpose.body.joint_fit import fit_pose_to_points
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.tracking.result import BodyResult, posed_skeleton


def body_at_joints(body: BodyResult, skinned: SkinnedBody, intrinsics: Intrinsics, start: np.ndarray,
                   joints: np.ndarray) -> BodyResult:
    """``body`` (with a pose, fitted with ``skinned``) moved towards ``joints`` (J, 3) m, camera frame,
    ``EVAL_JOINTS`` order: its pose fitted from ``start`` (36,) so that the body's own points move as
    ``joints`` move from ``body.joints3d`` (a tracker's published joints may differ from ``skinned``'s
    points by a locked height); the published joints are ``body``'s moved as those points moved, the 2D
    joints their projections, the full joint set ``skeleton`` the fitted pose's, ``unfiltered`` what the
    search found (``body.found``). Where the targets
    are not finite, the pose is ``start``."""
    found = skinned.posed_points(body.pose[None], EVAL_JOINTS)[0]
    targets = found + joints - body.joints3d
    pose = (fit_pose_to_points(skinned, start, EVAL_JOINTS, targets)
            if np.all(np.isfinite(targets)) else np.asarray(start, dtype=np.float64))
    transforms = skinned.transforms(pose[None])
    joints3d = body.joints3d + skinned.points_at(transforms, EVAL_JOINTS)[0] - found
    return replace(body, pose=pose, joints3d=joints3d, joints2d=intrinsics.project(joints3d),
                   unfiltered=body.found, skeleton=posed_skeleton(skinned, pose, intrinsics, transforms))
