"""The tables ``cl/include/fk.h`` runs forward kinematics from, built once per body.

They encode the same rig as :class:`swarmpose.body.kinematics.Rig` and the tracking joints of
:mod:`swarmpose.body.skeleton`, so the device's FK of a pose equals
:func:`swarmpose.body.kinematics.skinning_transforms` (the oracle) to float32 rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpose.body.skeleton import ANGLES, TRACKING_JOINTS, angle_offset
from swarmpose.body.skinned import SkinnedBody

MAX_STEPS = 3
"""Rotations per tracking joint (roll, pitch, yaw at most)."""


@dataclass(frozen=True)
class FkTables:
    """steps: (NJ·3, 4) float32, each joint's rotations in multiplication order (unit axis,
    pose-vector index of the angle; index -1: no step); links: (NB, 2) int32 (parent bone or
    -1, tracking joint or -1); bone_data: (NB·4, 4) float32 (rest head m and the joint's
    share, then the three rows of the rest frame's transpose); point_bone: (NPT,) int32 and
    point_rest: (NPT, 4) float32 the named points (body frame, m)."""

    steps: np.ndarray
    links: np.ndarray
    bone_data: np.ndarray
    point_bone: np.ndarray
    point_rest: np.ndarray

    @property
    def defines(self) -> dict[str, int]:
        """The kernel's compile-time sizes NJ and NPT."""
        return {"NJ": len(self.steps) // MAX_STEPS, "NPT": len(self.point_bone)}


def joint_steps() -> np.ndarray:
    """(NJ·3, 4) float32: every tracking joint's rotations in ``compose`` order (see
    :func:`swarmpose.body.kinematics.compose_joint`)."""
    steps = np.zeros((len(TRACKING_JOINTS) * MAX_STEPS, 4), np.float32)
    steps[:, 3] = -1.0
    for j, joint in enumerate(TRACKING_JOINTS):
        kinds = [d.kind for d in joint.dofs]
        first = ANGLES.start + angle_offset(joint.name)
        for k, kind in enumerate(joint.compose):
            dof = kinds.index(kind)
            axis = np.asarray(joint.dofs[dof].axis, float)
            steps[MAX_STEPS * j + k] = (*(axis / np.linalg.norm(axis)), first + dof)
    return steps


def fk_tables(body: SkinnedBody) -> FkTables:
    """The device FK tables of ``body``'s rig and named points."""
    rig = body.rig
    nb = len(rig.parents)
    links = np.stack([rig.parents, rig.bone_joint], axis=1).astype(np.int32)
    data = np.zeros((nb, 4, 4), np.float32)
    data[:, 0, :3] = rig.heads
    data[:, 0, 3] = rig.bone_fraction
    data[:, 1:, :3] = np.swapaxes(rig.rest_frames, -1, -2)
    point_rest = np.zeros((len(body.point_bones), 4), np.float32)
    point_rest[:, :3] = body.point_rest
    return FkTables(joint_steps(), np.ascontiguousarray(links), data.reshape(nb * 4, 4),
                    np.ascontiguousarray(body.point_bones, np.int32), point_rest)
