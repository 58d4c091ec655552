"""Particle swarm optimisation with bounds, as the paper uses it (§2.4), and its perturbed variant.

Update (Clerc & Kennedy's constriction, the paper's ref [6]):
``V ← ω (V + c1 r1 (P_i − x) + c2 r2 (G − x))``, ``x ← x + V``, with c1 = 2.8, c2 = 1.3,
ψ = c1 + c2 and ω = 2 / |2 − ψ − sqrt(ψ² − 4ψ)| ≈ 0.7298; r1, r2 ~ U(0, 1) per dimension.
The paper's Eq. (7) as printed puts ω on the inertia term only; with ψ = 4.1 that swarm
does not converge (``tests/test_pso.py`` shows it on test functions), so the constriction
form is the default and the printed one is kept as ``update="printed"`` for comparison.

Bounds: when a step would leave [lo, hi] in a dimension, that velocity component is
shrunk so the particle lands on the bound (the paper's rule). ``project`` maps positions
back onto a constraint set after each step (the tracker renormalises the quaternion).

Perturbed variant (after the paper's ref [26]): every ``perturb_every`` generations a
random ``perturb_fraction`` of the particles (never the one holding the global best) is
moved by a caller-supplied ``perturb`` function and loses its velocity; personal bests
are kept, so a perturbation can only add exploration.

Sub-swarms (``groups``): in the generations before ``merge_at`` each particle follows the best
of its own group instead of the swarm's (a local-best topology of disjoint groups, as niching PSOs
keep several basins apart); from then on all follow the global best. A group started around
a hypothesis far from the rest (the tracker's limb flips) is refined in its own basin before
it competes, instead of being pulled at once towards a best that is better only because the
rest of the hypothesis' pose has not been refined yet. The group bests are never perturbed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmpose.core.errors import ConfigError
from swarmpose.tracking.config import VARIANTS, tracker_default

UPDATES = ("constriction", "printed")


def constriction_factor(c1: float, c2: float) -> float:
    """ω = 2 / |2 − ψ − sqrt(ψ² − 4ψ)| with ψ = c1 + c2 > 4."""
    psi = c1 + c2
    if psi <= 4:
        raise ConfigError(f"constriction needs c1 + c2 > 4, got {psi}")
    return 2.0 / abs(2.0 - psi - np.sqrt(psi * psi - 4.0 * psi))


@dataclass(frozen=True)
class PsoConfig:
    """Swarm size, budget and constants. ``variant`` canonical|perturbed, ``update`` constriction|printed."""

    particles: int = tracker_default("particles")
    generations: int = tracker_default("generations")
    c1: float = 2.8
    c2: float = 1.3
    variant: str = tracker_default("pso")
    update: str = "constriction"
    perturb_every: int = 8
    perturb_fraction: float = 0.5

    def __post_init__(self) -> None:
        if self.particles < 1 or self.generations < 1:
            raise ConfigError(f"PSO needs at least 1 particle and 1 generation, got {self.particles} and "
                              f"{self.generations}")
        if self.variant not in VARIANTS:
            raise ConfigError(f"PSO variant must be one of {VARIANTS}, got {self.variant!r}")
        if self.update not in UPDATES:
            raise ConfigError(f"PSO update must be one of {UPDATES}, got {self.update!r}")
        if self.perturb_every < 1 or not 0.0 <= self.perturb_fraction <= 1.0:
            raise ConfigError("perturb_every must be >= 1 and perturb_fraction within 0..1")

    @property
    def omega(self) -> float:
        return constriction_factor(self.c1, self.c2)


@dataclass(frozen=True)
class PsoResult:
    """best: (D,) position; value: its objective; history: (G + 1,) best value after
    initialisation and after each generation; evaluations: objective evaluations made;
    personal_bests (P, D) and personal_values (P,): every particle's best position and value
    at the end (the best among them is ``best``)."""

    best: np.ndarray
    value: float
    history: np.ndarray
    evaluations: int
    personal_bests: np.ndarray
    personal_values: np.ndarray

    def best_among(self, chosen: np.ndarray) -> int | None:
        """The index of the lowest finite personal value among the particles ``chosen`` (P,) bool
        selects (the tracker's: those of one facing); None when none of them has one."""
        rows = np.flatnonzero(chosen & np.isfinite(self.personal_values))
        return int(rows[np.argmin(self.personal_values[rows])]) if rows.size else None


def _step_within(x: np.ndarray, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The velocity shrunk per component so that x + v stays within [lo, hi]."""
    return np.clip(x + v, lo, hi) - x


def group_members(groups: np.ndarray) -> list[np.ndarray]:
    """The particle indices of each group of ``groups`` (P,) labels, in label order (once per run:
    the groups do not change)."""
    return [np.flatnonzero(groups == label) for label in np.unique(groups)]


def group_leaders(values: np.ndarray, members: list[np.ndarray]) -> np.ndarray:
    """(P,) for each particle the index of the lowest of ``values`` (P,) within its group
    (``members``: :func:`group_members`)."""
    lead = np.empty(len(values), dtype=int)
    for rows in members:
        lead[rows] = rows[np.argmin(values[rows])]
    return lead


def minimise(objective: Callable[[np.ndarray], np.ndarray], start: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             rng: np.random.Generator, config: PsoConfig = PsoConfig(),
             project: Callable[[np.ndarray], np.ndarray] | None = None,
             perturb: Callable[[np.ndarray, np.random.Generator], np.ndarray] | None = None,
             refine_at: int = 0, refine: Callable[[], None] | None = None,
             groups: np.ndarray | None = None, merge_at: int = 0) -> PsoResult:
    """Minimise ``objective`` (P, D) -> (P,) from initial positions ``start`` (P, D).

    lo, hi: (D,) bounds (±inf allowed); start is clipped into them. Generation 0 evaluates
    the start; each of ``config.generations`` further generations moves and evaluates all
    particles, so the objective sees ``P·(G + 1)`` hypotheses.

    Coarse to fine: with ``refine`` and 0 < ``refine_at`` <= G, ``refine()`` is called before
    generation ``refine_at`` (it switches ``objective`` to its final, finer form) and the
    personal bests are scored again with it (P more hypotheses), so that values of the two
    forms never compete.

    groups: (P,) integer labels of the sub-swarms (see the module docstring), followed apart in
    generations 1 .. ``merge_at`` - 1; None: one swarm throughout.
    """
    x = np.clip(np.array(start, dtype=np.float64), lo, hi)
    if groups is not None and np.shape(groups) != (len(x),):
        raise ConfigError(f"groups has shape {np.shape(groups)}, expected ({len(x)},): one label per particle")
    if project is not None:
        x = project(x)
    p_count, dim = x.shape
    v = np.zeros_like(x)
    values = np.asarray(objective(x), dtype=np.float64)
    values = np.where(np.isfinite(values), values, np.inf)
    pbest, pbest_val = x.copy(), values.copy()
    g = int(np.argmin(pbest_val))
    history = [pbest_val[g]]
    members = group_members(groups) if groups is not None else None
    omega = config.omega
    perturbing = config.variant == "perturbed" and perturb is not None
    evaluations = p_count * (config.generations + 1)
    for k in range(1, config.generations + 1):
        if refine is not None and k == refine_at:
            refine()
            pbest_val = np.asarray(objective(pbest), dtype=np.float64)
            pbest_val = np.where(np.isfinite(pbest_val), pbest_val, np.inf)
            g = int(np.argmin(pbest_val))
            evaluations += p_count
        r1, r2 = rng.random((2, p_count, dim))
        lead = group_leaders(pbest_val, members) if members is not None and k < merge_at else None
        social = pbest[g] if lead is None else pbest[lead]
        pull = config.c1 * r1 * (pbest - x) + config.c2 * r2 * (social - x)
        v = omega * (v + pull) if config.update == "constriction" else pull + omega * v
        v = _step_within(x, v, lo, hi)
        x = x + v
        if project is not None:
            x = project(x)
        if perturbing and k % config.perturb_every == 0:
            chosen = np.flatnonzero(rng.random(p_count) < config.perturb_fraction)
            chosen = chosen[(chosen != g) & ~np.isin(chosen, () if lead is None else lead)]
            if chosen.size:
                x[chosen] = np.clip(perturb(x[chosen], rng), lo, hi)
                if project is not None:
                    x[chosen] = project(x[chosen])
                v[chosen] = 0.0
        values = np.asarray(objective(x), dtype=np.float64)
        values = np.where(np.isfinite(values), values, np.inf)
        better = values < pbest_val
        pbest[better], pbest_val[better] = x[better], values[better]
        g = int(np.argmin(pbest_val))
        history.append(pbest_val[g])
    return PsoResult(pbest[g].copy(), float(pbest_val[g]), np.array(history), evaluations, pbest, pbest_val)
