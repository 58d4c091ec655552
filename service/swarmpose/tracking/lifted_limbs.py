"""Live frames' limb seeds: the last pose's arms and legs solved to this frame's lifted joints.

A live frame's search is short (6-8 generations at 60 ms on 2 cores) and skips the limb flips and
arm proposals (:func:`~swarmpose.tracking.budget.lean_frame`), while the frames between two tracked
ones leave the limbs a long way to go: a walker's wrists and ankles fell behind and the track
drifted off the person. The detection says where the limbs are now. So, on such a frame, each arm
and leg whose middle and end joints lift (J^e, :mod:`swarmpose.tracking.lift`) and lie more than
:data:`FAR_M` from where the base pose has them is solved to them
(:func:`~swarmpose.tracking.limb_flips.solve_limbs`, :data:`STEPS` Gauss-Newton steps, all limbs in
one batch), and the base pose with every solved limb joins the swarm as one particle. The bases are
the J^e torso (the last pose's angles on the torso the detection shows) and where the last two
poses' motion leads: the limbs hang from a torso that has moved too. The objective decides, as for
every seed.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skinned import SkinnedBody
from swarmpose.tracking.limb_flips import FLIP_LIMBS, limb_columns, solve_limbs
from swarmpose.tracking.objective import JointTargets

FAR_M = 0.08
"""A limb whose middle and end joints both lie within this of their lifts (m) is left as it is."""
STEPS = 2
"""Gauss-Newton steps of the solve: the seed only has to come near, the swarm refines it."""


def lifted_targets(targets: JointTargets) -> tuple[list[tuple[str, str, str]], np.ndarray]:
    """The limbs of :data:`~swarmpose.tracking.limb_flips.FLIP_LIMBS` whose middle and end joints
    both have a lift in ``targets``, and those lifts (K, 2, 3) m."""
    index = {name: k for k, name in enumerate(targets.names)}
    limbs, lifts = [], []
    for limb in FLIP_LIMBS:
        _, middle, end = limb
        if middle in index and end in index:
            pair = targets.xyz[[index[middle], index[end]]]
            if np.all(np.isfinite(pair)):
                limbs.append(limb)
                lifts.append(pair)
    return limbs, np.asarray(lifts, dtype=np.float64).reshape(-1, 2, 3)


def lifted_limb_seeds(body: SkinnedBody, bases: list[np.ndarray], targets: JointTargets) -> list[np.ndarray]:
    """Per base pose (36,): a copy with every limb that lies farther than :data:`FAR_M` from its
    lifted joints solved to them (none where no limb does, or none lifts)."""
    limbs, lifts = lifted_targets(targets)
    if not limbs or not bases:
        return []
    names = tuple(n for limb in limbs for n in limb[1:])
    now = body.posed_points(np.asarray(bases, dtype=np.float64), names).reshape(len(bases), -1, 2, 3)
    far = np.linalg.norm(now - lifts, axis=3).max(axis=2) > FAR_M  # (bases, limbs)
    starts, chosen, goals = [], [], []
    for b, k in zip(*np.nonzero(far)):
        starts.append(bases[b])
        chosen.append((int(b), limbs[k]))
        goals.append(lifts[k])
    if not chosen:
        return []
    solved, _ = solve_limbs(body, np.asarray(starts, dtype=np.float64), [limb for _, limb in chosen],
                            np.asarray(goals), steps=STEPS, misses=False)
    seeds = {b: np.array(bases[b], dtype=np.float64) for b, _ in chosen}
    for (b, limb), pose in zip(chosen, solved):
        cols = limb_columns(limb)
        seeds[b][cols] = pose[cols]
    return [seeds[b] for b in sorted(seeds)]
