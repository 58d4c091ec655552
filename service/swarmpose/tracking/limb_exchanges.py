"""Left and right limbs exchanged: poses whose left leg swings as the right one did, and the other way round.

Where a person's legs (or arms) pass each other, seen from the side most of all, the track can take
each leg for the other: its left leg then reaches across to where the right one is. The depth
cannot tell the two apart (the same surfaces are covered), and the joint term's left/right matching
(:data:`~swarmpose.tracking.objective.SWAP_COST`) lets the crossed labels cost only a little, so the
exchanged fit holds for as long as the legs stay apart. Undoing it moves both legs at once, a jump
the per-frame search (a fraction of a radian around the last pose) does not make.

So each frame on which the previous solution stands side on (:data:`SIDE_ON_SHARE`), its legs, and
its arms, are exchanged: each limb's middle and end points are sent to where the other side's limb has
them relative to its pivot, mirrored through the body's midplane (the plane across the line between
the two pivots) and set at its own pivot. The stride and the arms' swing change sides, each limb stays
on its own side of the body, and a pose whose two sides are alike (standing, arms held out) gives
itself back. Each limb's four angles are solved to them
(:func:`~swarmpose.tracking.limb_flips.solve_limbs`) from the other side's angles mirrored
(:data:`MIRROR_SIGNS`). Each exchanged pose joins the frame's swarm as a particle; the objective
decides, as it does for the depth flips.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import ANGLE_LIMITS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.tracking.limb_flips import FLIP_LIMBS, MAX_MISS_M, limb_columns, solve_limbs
from swarmpose.tracking.objective import side_on_share

EXCHANGED_PAIRS: tuple[tuple[tuple[str, str, str], tuple[str, str, str]], ...] = (
    (FLIP_LIMBS[1], FLIP_LIMBS[3]),  # the legs: (left hip, knee, ankle), (right hip, knee, ankle)
    (FLIP_LIMBS[0], FLIP_LIMBS[2]),  # the arms
)
"""(left limb, right limb) pairs whose swings are exchanged, the legs first."""
SIDE_ON_SHARE = 0.7
"""Exchanges are tried only for a pose at least this side on (:func:`~swarmpose.tracking.objective.side_on_share`,
0.7: within 45° of side on), where the two sides' limbs cover each other in the image. Facing the
camera or turned away, the limbs lie apart, and what swaps there is a network's labels (from behind
most of all), which an exchange would follow (BENCHMARKS.md, issue 53, "Limbs exchanged")."""
MIRROR_SIGNS = (np.array([-1.0, 1.0, -1.0, 1.0]), np.array([-1.0, 1.0, -1.0, -1.0]))
"""Per pair of :data:`EXCHANGED_PAIRS`, the signs that turn one side's four angles (pivot's three, the
middle joint's one; :func:`~swarmpose.tracking.limb_flips.limb_columns`) into the other side's mirror
image: exact for the legs; for the arms within the collars' asymmetry (1-2 cm at the wrist), which
the solve takes up. Where a swing is far from the limb's own, the solve needs this start: from the
limb's own angles it misses by decimetres after its few steps."""


def exchange_targets(at: dict[str, np.ndarray], limb: tuple[str, str, str],
                     other: tuple[str, str, str]) -> np.ndarray:
    """(2, 3) m: ``limb``'s middle and end points placed as ``other``'s are relative to its pivot,
    mirrored through the midplane between the two pivots, from the points ``at`` (name → (3,) m) of one
    pose; ``other``'s own points where the pivots coincide."""
    across = at[limb[0]] - at[other[0]]
    length = float(np.linalg.norm(across))
    normal = across / length if length > 0.0 else np.zeros(3)
    swing = np.stack([at[other[1]], at[other[2]]]) - at[other[0]]
    mirrored = swing - 2.0 * (swing @ normal)[:, None] * normal
    return at[limb[0]] + mirrored


def mirrored_start(pose: np.ndarray, pair: int) -> np.ndarray:
    """``pose`` (36,) with the two limbs of ``EXCHANGED_PAIRS[pair]`` given each other's angles through
    :data:`MIRROR_SIGNS` (clipped to the joint limits)."""
    left, right = EXCHANGED_PAIRS[pair]
    out = pose.copy()
    for limb, other in ((left, right), (right, left)):
        out[limb_columns(limb)] = pose[limb_columns(other)] * MIRROR_SIGNS[pair]
    out[7:] = np.clip(out[7:], ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1])
    return out


def limb_exchanges(body: SkinnedBody, pose: np.ndarray, most: int | None = None) -> list[np.ndarray]:
    """The poses (36,) of ``pose`` (36,) with the legs' and then the arms' swings exchanged (module
    doc), those whose solved limbs all reach within :data:`~swarmpose.tracking.limb_flips.MAX_MISS_M`
    of their targets; at most ``most`` pairs (None: both); none unless ``pose`` stands at least
    :data:`SIDE_ON_SHARE` side on. Each pair starts from
    :func:`mirrored_start`; its two limbs, independent chains, are solved in one batch with the
    other pair's."""
    pairs = EXCHANGED_PAIRS[:most]
    pose = np.asarray(pose, float)
    if not pairs or side_on_share(pose) < SIDE_ON_SHARE:
        return []
    limbs = [limb for pair in pairs for limb in pair]
    names = tuple(n for limb in limbs for n in limb)
    at = dict(zip(names, body.posed_points(pose[None], names)[0]))
    targets = np.stack([exchange_targets(at, limb, other) for left, right in pairs
                        for limb, other in ((left, right), (right, left))])
    starts = np.stack([mirrored_start(pose, k) for k in range(len(pairs)) for _ in range(2)])
    solved, miss = solve_limbs(body, starts, limbs, targets)
    out = []
    for k in range(len(pairs)):
        if max(miss[2 * k], miss[2 * k + 1]) > MAX_MISS_M:
            continue
        exchanged = pose.copy()
        for row in (2 * k, 2 * k + 1):
            columns = limb_columns(limbs[row])
            exchanged[columns] = solved[row, columns]
        out.append(exchanged)
    return out
