"""Position channels of non-root BVH joints: local offsets, or positions in the root's frame.

The BVH format says a joint's position channels replace its OFFSET: a translation from the
parent, in the parent's frame. Some exporters write instead where the joint *is*, in the same
frame as the root's position channels (CMU ASF conversions whose thorax and head carry six
channels do: their values are tens of units away from the offset, but their distance from the
parent's position is the bone's length). This module tells the two apart joint by joint and
turns the second kind into the first, so forward kinematics reproduces the file's positions.
"""

from __future__ import annotations

import numpy as np


def local_translations(parents: np.ndarray, offsets: np.ndarray, rotations: np.ndarray,
                       translations: np.ndarray, positioned: np.ndarray) -> np.ndarray:
    """Per-frame local translations (N, J, 3), file units, for forward kinematics.

    parents: (J,) parent index, -1 for the root (index 0, joints in topological order).
    offsets: (J, 3) rest offsets. rotations: (N, J, 3, 3) local rotations. translations:
    (N, J, 3) the position channels where a joint has them, else its offset (row 0 = the root's
    position). positioned: (J,) bool, the joints that have position channels.

    A non-root joint's channels are read as a local translation (the BVH meaning) unless the
    same values read as a position in the root's frame, taken back into the parent's frame
    (``G_parent^T (t - p_parent)``), lie clearly nearer its offset: within a quarter of the
    distance. Medians over frames decide, so a few odd frames do not flip the reading.
    """
    out = translations.copy()
    n, count = translations.shape[:2]
    rot = np.empty((n, count, 3, 3))
    pos = np.empty((n, count, 3))
    rot[:, 0] = rotations[:, 0]
    pos[:, 0] = translations[:, 0]
    for k in range(1, count):
        par = int(parents[k])
        if positioned[k]:
            as_global = np.einsum("nji,nj->ni", rot[:, par], translations[:, k] - pos[:, par])
            local_miss = np.median(np.linalg.norm(translations[:, k] - offsets[k], axis=-1))
            global_miss = np.median(np.linalg.norm(as_global - offsets[k], axis=-1))
            if global_miss < 0.25 * local_miss:
                out[:, k] = as_global
        pos[:, k] = pos[:, par] + np.einsum("nij,nj->ni", rot[:, par], out[:, k])
        rot[:, k] = rot[:, par] @ rotations[:, k]
    return out
