"""A swarm that searches the pose block by block: the live frame's short search.

With a frame budget a live frame's swarm runs 6-15 generations. A 36-D swarm that short improves
one limb only where the same move does not spoil another, so most of its moves are lost: 64
particles or 320 make no difference to it, only generations do. Here every particle moves one
block of the pose (:data:`BLOCKS`: the root, the trunk, each arm, each leg) and keeps the rest at
a pose the whole swarm shares, the *context*, so that a limb's sub-swarm is judged by that
limb's moves alone (cooperative PSO, van den Bergh and Engelbrecht's CPSO-S_K, IEEE TEC 8(3),
2004). All the blocks' sub-swarms are scored in the same launch, so a generation costs what the
36-D swarm's does.

Per generation, after the start (generation 0, scored whole as :func:`~swarmpose.tracking.pso.minimise`
scores it, whose best becomes the context):

* particle 0 is the context itself, so every other particle's value is read as its *gain* over
  the context of the same launch;
* the other particles, dealt to the blocks in turn, move their block's coordinates by the
  constriction update towards their own best and their sub-swarm's best (the lowest gain);
* then every block whose best gain is below 0 is taken into the context, and that sub-swarm's
  gains are counted from its new best. The blocks' gains add up only roughly (a limb moved in
  front of another's pixels), so a merged context that scores worse than the best pose scored so
  far gives way to that pose, and the gains counted from it are forgotten.

Every scored row is a whole pose, so the result is the best of all of them, and each particle's
personal best is the best whole pose it was part of (what the facing hold and the polish read).

A tracked frame (:func:`whole_then_blocks`) runs the whole-pose swarm for its first quarter of
generations, then the blocks: a body that turns moves every limb with its root, which sub-swarms
judged one block at a time follow badly (the turning walk from the front: 58 mm with the whole
swarm, 78 block by block from the first generation, 60 with the quarter first).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from swarmpose.core.errors import ConfigError
from swarmpose.tracking.pso import PsoConfig, PsoResult, group_leaders, group_members, minimise
from swarmpose.tracking.search import LIMB_COLUMNS

BLOCKS: tuple[np.ndarray, ...] = (np.arange(7), LIMB_COLUMNS[4], *LIMB_COLUMNS[:4])
"""Columns of the 36-D pose each sub-swarm moves: the root (translation and quaternion), the
trunk (spine and neck), the left and right arm (collar, shoulder, elbow), the left and right leg
(hip, knee, ankle). Together they hold every column once."""


def block_of_particles(particles: int, blocks: int) -> np.ndarray:
    """(P,) the block index each particle moves: -1 for particle 0 (the context), then the
    blocks in turn."""
    if particles < blocks + 1:
        raise ConfigError(f"a block search needs at least {blocks + 1} particles (the context and one per "
                          f"block), got {particles}")
    member = np.full(particles, -1)
    member[1:] = np.arange(particles - 1) % blocks
    return member


WHOLE_SHARE = 0.25
"""The share of a frame's generations the whole-pose swarm runs before the blocks (:func:`whole_then_blocks`)."""
PROPOSAL_SHARE = 0.5
"""At most this share of a block's sub-swarm starts at proposals (:func:`minimise_blocks`)."""


def changed_block(pose: np.ndarray, centre: np.ndarray, blocks: tuple[np.ndarray, ...] = BLOCKS) -> int | None:
    """The index of the one block in which ``pose`` (D,) differs from ``centre`` (D,); None when it
    differs in none or in several (a proposal that changes one limb of the previous pose names it)."""
    moved = [b for b, columns in enumerate(blocks) if np.any(pose[columns] != centre[columns])]
    return moved[0] if len(moved) == 1 else None


def _finite(values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    return np.where(np.isfinite(values), values, np.inf)


def _reference(context_value: float, best_value: float) -> float:
    """The value gains are counted from: the context's, or where it did not score, the best's (or 0)."""
    for value in (context_value, best_value):
        if np.isfinite(value):
            return float(value)
    return 0.0


def _start_at_proposals(position: np.ndarray, rows_of: list[np.ndarray], blocks: tuple[np.ndarray, ...],
                        proposals: Sequence[tuple[int, np.ndarray]], lo: np.ndarray, hi: np.ndarray) -> None:
    """Writes each proposal's block values over a particle of its block's sub-swarm (at least one
    per block), within [lo, hi] (in place)."""
    placed = [0] * len(blocks)
    for block, pose in proposals:
        rows = rows_of[block]
        if placed[block] >= max(int(PROPOSAL_SHARE * len(rows)), 1):
            continue
        placed[block] += 1
        position[rows[-placed[block]], blocks[block]] = np.asarray(pose)[blocks[block]]
    np.clip(position, lo, hi, out=position)


def minimise_blocks(objective: Callable[[np.ndarray], np.ndarray], start: np.ndarray, lo: np.ndarray,
                    hi: np.ndarray, rng: np.random.Generator, config: PsoConfig | None = None,
                    project: Callable[[np.ndarray], np.ndarray] | None = None,
                    blocks: tuple[np.ndarray, ...] = BLOCKS,
                    proposals: Sequence[tuple[int, np.ndarray]] = (),
                    start_values: np.ndarray | None = None) -> PsoResult:
    """Minimise ``objective`` (P, D) -> (P,) from ``start`` (P, D) block by block (module docstring).

    lo, hi: (D,) bounds; project: maps poses back onto the constraint set (the root quaternion's
    unit length); blocks: the columns each sub-swarm moves; proposals: (block index, pose (D,)) of
    hypotheses that change one block (a limb flipped in depth, an arm sent to unexplained depth):
    each starts a particle of its block's sub-swarm at its values, the sub-swarm's last particles
    first, at most :data:`PROPOSAL_SHARE` of it, so that the hypothesis is judged in the context
    the other blocks refine rather than against it. start_values: (P,) the objective's values of
    ``start`` where they are known (generation 0 then scores nothing). ``config`` gives the particles' count
    (that of ``start``), the generations and c1, c2 (None: the defaults); the variant's perturbation is not used.
    The objective sees ``P·(G + 1)`` poses, as :func:`~swarmpose.tracking.pso.minimise`'s does
    (``P·G`` with ``start_values``).
    """
    config = config or PsoConfig()
    x = np.clip(np.array(start, dtype=np.float64), lo, hi)
    if project is not None:
        x = project(x)
    count, dim = x.shape
    member = block_of_particles(count, len(blocks))
    mask = np.zeros((count, dim), dtype=bool)
    for i in range(1, count):
        mask[i, blocks[member[i]]] = True
    values = _finite(objective(x) if start_values is None else start_values)
    whole, whole_values = x.copy(), values.copy()  # each particle's best whole pose
    g = int(np.argmin(values))
    best, best_value = x[g].copy(), float(values[g])
    history = [best_value]
    context = best.copy()
    position, velocity = x.copy(), np.zeros_like(x)  # a particle's own block in its block's columns
    members = group_members(member)  # the context alone, then each block's sub-swarm
    rows_of = members[1:]
    _start_at_proposals(position, rows_of, blocks, proposals, lo, hi)
    own, own_gain = position.copy(), np.full(count, np.inf)
    omega = config.omega
    for k in range(1, config.generations + 1):
        if k > 1:  # generation 1 scores the start's blocks in the context
            lead = own[group_leaders(own_gain, members)]
            r1, r2 = rng.random((2, count, dim))
            pull = config.c1 * r1 * (own - position) + config.c2 * r2 * (lead - position)
            velocity = np.where(mask, omega * (velocity + pull), 0.0)
            velocity = np.clip(position + velocity, lo, hi) - position
            position = position + velocity
        trial = np.where(mask, position, context[None])
        if project is not None:
            trial = project(trial)
            position = np.where(mask, trial, position)
        values = _finite(objective(trial))
        gain = values - _reference(values[0], best_value)
        better = gain < own_gain
        own[better], own_gain[better] = position[better], gain[better]
        improved = values < whole_values
        whole[improved], whole_values[improved] = trial[improved], values[improved]
        g = int(np.argmin(values))
        merge_failed = values[0] > best_value  # the last merge scored worse than a pose before it
        if values[g] < best_value:
            best, best_value = trial[g].copy(), float(values[g])
        if merge_failed:  # back to the best pose scored; gains counted from the discarded context are void
            context = best.copy()
            own_gain[:] = np.inf
        for b, rows in enumerate(rows_of):
            leader = rows[np.argmin(own_gain[rows])]
            if own_gain[leader] < 0:
                context[blocks[b]] = own[leader, blocks[b]]
                own_gain[rows] -= own_gain[leader]
        if project is not None:
            context = project(context[None])[0]
        history.append(best_value)
    scored = count * (config.generations + (start_values is None))
    return PsoResult(best.copy(), best_value, np.array(history), scored, whole, whole_values)


def whole_then_blocks(objective: Callable[[np.ndarray], np.ndarray], start: np.ndarray, lo: np.ndarray,
                      hi: np.ndarray, rng: np.random.Generator, config: PsoConfig,
                      project: Callable[[np.ndarray], np.ndarray] | None = None,
                      perturb: Callable[[np.ndarray, np.random.Generator], np.ndarray] | None = None,
                      proposals: Sequence[tuple[int, np.ndarray]] = ()) -> PsoResult:
    """A tracked frame's search: :data:`WHOLE_SHARE` of ``config.generations`` (at least 1) by the
    whole-pose swarm (:func:`~swarmpose.tracking.pso.minimise`, with ``perturb``), then the rest
    block by block (:func:`minimise_blocks`, ``proposals`` as there) from the swarm's personal
    bests, best first. The root and trunk settle first, as a whole: a body that turns moves every
    limb with it, which the limbs' sub-swarms, each judged in the shared pose, follow badly. The
    objective sees ``P·(G + 1)`` poses in all. ``start``, lo, hi, rng and project: as
    :func:`minimise_blocks`."""
    first = max(int(round(WHOLE_SHARE * config.generations)), 1)
    head = minimise(objective, start, lo, hi, rng, replace(config, generations=first), project, perturb)
    if config.generations <= first:
        return head
    order = np.argsort(head.personal_values, kind="stable")
    tail = minimise_blocks(objective, head.personal_bests[order], lo, hi, rng,
                           replace(config, generations=config.generations - first), project,
                           proposals=proposals, start_values=head.personal_values[order])
    history = np.concatenate([head.history, tail.history[1:]])
    return replace(tail, history=history, evaluations=head.evaluations + tail.evaluations)
