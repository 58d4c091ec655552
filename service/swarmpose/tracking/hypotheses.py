"""Sub-swarms for the frame's best hypotheses: limb flips and arm proposals refined apart from the track.

The depth flips (:mod:`swarmpose.tracking.limb_flips`) and arm proposals
(:mod:`swarmpose.tracking.arm_proposals`) change one limb of the previous solution and keep the
rest of it, a frame old. Joined to the swarm as single particles, such a hypothesis scores worse
than the continued track even where its limb is the right one, because the track's particles
have refined the rest of the pose to this frame and the hypothesis has not; the swarm's best
pulls it over at once, so a right proposal is lost.

So the best :attr:`TrackerConfig.hypotheses` of them by the objective each start a sub-swarm of
:data:`GROUP_SHARE` of the particles (at least 2), spread around it at half the track's search
radii. In the generations before :data:`MERGE_SHARE` of the budget (1-47 of 64) each group
follows its own best (:func:`swarmpose.tracking.pso.minimise`'s ``groups``), then all follow the
best of all: a hypothesis competes after it has been refined in its own basin.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from swarmpose.tracking import search

GROUP_SHARE = 12 / 64
"""Share of the swarm's particles in each hypothesis' sub-swarm (12 of the default 64)."""
MERGE_SHARE = 0.75
"""The sub-swarms follow their own bests in the generations before this share of the budget
(``merge_at`` = 48 of 64: generations 1-47)."""
SPREAD_SHARE = 0.5
"""A sub-swarm's start region: this share of the track's angle radii, ±2 cm and ±0.05 rad at the root."""


def hypothesis_groups(score: Callable[[np.ndarray], np.ndarray], proposals: Sequence[np.ndarray],
                      start: np.ndarray, count: int, angle_radius: float | np.ndarray,
                      rng: np.random.Generator, keep: int = 2) -> np.ndarray | None:
    """Sub-swarms around the ``count`` best of ``proposals`` (each (36,)) by ``score`` ((N, 36) ->
    (N,); non-finite scores never get one), written over the last particles of ``start`` (P, 36)
    in place, below which its first ``keep`` rows (the track's own seeds) stay untouched; returns
    the (P,) group labels (0: the track's swarm, k: the k-th best hypothesis), or None when no
    sub-swarm of at least 2 particles fits (no proposal, ``count`` 0, or too few particles beyond
    ``keep``). ``angle_radius``: the track's per-frame angle radii (scalar or (29,), rad). A
    proposal without a sub-swarm whose row a block covers is dropped."""
    particles = len(start)
    size = max(int(round(GROUP_SHARE * particles)), 2)
    count = min(count, len(proposals), (particles - max(keep, 2)) // size)
    if count <= 0:
        return None
    values = np.asarray(score(np.stack(proposals)), dtype=float)
    ranked = [int(i) for i in np.argsort(values) if np.isfinite(values[i])][:count]
    if not ranked:
        return None
    groups = np.zeros(particles, dtype=int)
    for rank, index in enumerate(ranked):
        block_end = particles - rank * size
        block = search.spread(proposals[index], size, rng, np.full(3, 0.02), 0.05,
                              SPREAD_SHARE * np.asarray(angle_radius))
        block[0] = proposals[index]
        start[block_end - size:block_end] = block
        groups[block_end - size:block_end] = rank + 1
    return groups
