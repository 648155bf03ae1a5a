"""Fitness of one population member from its episodes and maps (the formula lives here only).

Each member samples K maps from seeds shared by the whole generation; each map is one
episode of the robot under test. With ``w_*`` the weights of ``FitnessConfig``::

    fitness =   w_risk      * mean FAULT risk score over the member's FEASIBLE episodes
              + w_proximity * mean (proximity_time / simulation_time) over FEASIBLE episodes
              - w_infeasible * (fraction of the K maps that are infeasible)
              - w_tpkl      * max(0, tpkl / tpkl_reference - 1 - tpkl_tolerance)
              + w_diversity * diversity of the member's K maps

* fault risk score = fault_collisions * proximity_time / simulation_time: the paper's risk
  score (reported unchanged beside it) over the contacts the robot under test caused, so an
  agent ramming a standing robot earns nothing (sessgan_sim.metrics). Only FEASIBLE maps
  (valid tests with a certified route) count. It is 0 for every episode without a fault
  collision, which is most episodes early on, so selection would be blind; the proximity
  term is a small shaping signal (near misses) that rewards getting close before the first
  collision is found. It is bounded by ``w_proximity`` (the fraction lies in [0, 1]).
* tpkl: the tile-pattern KL divergence of the member's K maps to the example map;
  tpkl_reference: that of generation 0 (``tpkl_reference_from``), so the penalty measures
  drift relative to the pre-trained generator rather than an absolute level.
* diversity: mean pairwise Hamming distance fraction of the K maps (``map_diversity``),
  which discourages collapsing onto one adversarial map.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from sessgan_core.validation import require_non_negative
from sessgan_evolver.errors import FitnessError


class EpisodeMetricsLike(Protocol):
    """What fitness reads from an episode result (sessgan_sim's metrics, a message, ...)."""

    collisions: int
    proximity_time: float
    simulation_time: float
    risk_score: float
    fault_collisions: int
    fault_risk_score: float
    feasible: bool


@dataclass(frozen=True)
class FitnessConfig:
    """Weights of the fitness formula (module docstring); defaults in brackets."""

    risk_weight: float = 1.0
    """[1.0] w_risk: weight of the mean fault risk score over feasible episodes."""
    proximity_weight: float = 0.1
    """[0.1] w_proximity: weight of the shaping term, mean proximity_time / simulation_time
    over feasible episodes (0 disables shaping; the term is at most this weight)."""
    infeasible_weight: float = 1.0
    """[1.0] w_infeasible: penalty per unit fraction of infeasible maps (all K maps
    infeasible costs 1.0, more than a typical risk score of a few tenths)."""
    tpkl_weight: float = 1.0
    """[1.0] w_tpkl: penalty per unit of relative TPKL drift above the reference."""
    tpkl_tolerance: float = 0.0
    """[0.0] Relative drift allowed before the TPKL penalty starts (0.2: 20 % above the
    reference is free)."""
    diversity_weight: float = 0.1
    """[0.1] w_diversity: weight of the maps' mean pairwise Hamming fraction in [0, 1]."""
    tpkl_reference_floor: float = 1e-6
    """[1e-6] The reference TPKL is raised to at least this (nats) before dividing."""

    def validate(self) -> None:
        """Raise FitnessError naming the first invalid field."""
        for name, value in asdict(self).items():
            require_non_negative(f'fitness config {name}', value, FitnessError)
        if self.tpkl_reference_floor <= 0.0:
            raise FitnessError('tpkl_reference_floor must be > 0')


@dataclass(frozen=True)
class FitnessBreakdown:
    """A member's fitness and every term and metric behind it (one CSV row's worth).

    Metric means are over FEASIBLE episodes (controller faults count only there); they are
    None when the member had no feasible episode.
    """

    fitness: float
    episodes: int
    feasible_episodes: int
    feasible_fraction: float
    risk_score: float | None
    """Mean risk score (paper's definition) over feasible episodes."""
    collisions: float | None
    """Mean collision count over feasible episodes."""
    fault_risk_score: float | None
    """Mean fault risk score over feasible episodes (the risk term's base)."""
    fault_collisions: float | None
    """Mean fault collision count over feasible episodes."""
    proximity_time: float | None
    """Mean proximity time over feasible episodes, sim seconds."""
    simulation_time: float | None
    """Mean simulation time over feasible episodes, sim seconds."""
    proximity_fraction: float | None
    """Mean proximity_time / simulation_time over feasible episodes."""
    risk_score_all: float
    """Mean risk score over all episodes, feasible or not."""
    risk_term: float
    proximity_term: float
    infeasible_penalty: float
    tpkl: float | None
    tpkl_reference: float | None
    tpkl_ratio: float | None
    tpkl_penalty: float
    diversity: float | None
    diversity_bonus: float

    def as_row(self) -> dict[str, Any]:
        """The breakdown as a flat dict of plain values."""
        return asdict(self)


def member_fitness(episodes: Sequence[EpisodeMetricsLike | Mapping[str, Any]],
                   tpkl: float | None = None, tpkl_reference: float | None = None,
                   diversity: float | None = None,
                   config: FitnessConfig | None = None) -> FitnessBreakdown:
    """The fitness of one member (formula in the module docstring).

    ``episodes``: the member's K episode results (objects or mappings with collisions,
    fault_collisions, proximity_time, simulation_time, risk_score, fault_risk_score,
    feasible). ``tpkl``/``tpkl_reference``:
    nats; None skips the TPKL penalty. ``diversity``: in [0, 1]; None gives no bonus.
    """
    config = config or FitnessConfig()
    config.validate()
    if not episodes:
        raise FitnessError('a member needs at least one episode to have a fitness')
    rows = [_episode_values(index, episode) for index, episode in enumerate(episodes)]
    feasible = [row for row in rows if row['feasible']]
    count, feasible_count = len(rows), len(feasible)
    infeasible_fraction = 1.0 - feasible_count / count

    def feasible_mean(key: str) -> float | None:
        return float(np.mean([row[key] for row in feasible])) if feasible else None

    risk = feasible_mean('risk_score')
    fault_risk = feasible_mean('fault_risk_score')
    proximity_fraction = feasible_mean('proximity_fraction')
    risk_term = config.risk_weight * (fault_risk or 0.0)
    proximity_term = config.proximity_weight * (proximity_fraction or 0.0)
    infeasible_penalty = config.infeasible_weight * infeasible_fraction

    tpkl_ratio = None
    tpkl_penalty = 0.0
    if tpkl is not None and tpkl_reference is not None:
        require_non_negative('tpkl', tpkl, FitnessError)
        tpkl_ratio = tpkl / max(tpkl_reference, config.tpkl_reference_floor)
        tpkl_penalty = config.tpkl_weight * max(0.0, tpkl_ratio - 1.0 - config.tpkl_tolerance)

    diversity_bonus = 0.0
    if diversity is not None:
        if not 0.0 <= diversity <= 1.0:
            raise FitnessError(f'diversity must lie in [0, 1], got {diversity}')
        diversity_bonus = config.diversity_weight * diversity

    fitness = risk_term + proximity_term - infeasible_penalty - tpkl_penalty + diversity_bonus
    return FitnessBreakdown(
        fitness=fitness, episodes=count, feasible_episodes=feasible_count,
        feasible_fraction=feasible_count / count, risk_score=risk,
        collisions=feasible_mean('collisions'), fault_risk_score=fault_risk,
        fault_collisions=feasible_mean('fault_collisions'),
        proximity_time=feasible_mean('proximity_time'),
        simulation_time=feasible_mean('simulation_time'),
        proximity_fraction=proximity_fraction,
        risk_score_all=float(np.mean([row['risk_score'] for row in rows])),
        risk_term=risk_term, proximity_term=proximity_term,
        infeasible_penalty=infeasible_penalty, tpkl=tpkl, tpkl_reference=tpkl_reference,
        tpkl_ratio=tpkl_ratio, tpkl_penalty=tpkl_penalty, diversity=diversity,
        diversity_bonus=diversity_bonus)


def map_diversity(maps: Sequence[np.ndarray]) -> float:
    """Mean pairwise Hamming distance fraction of equally shaped maps, in [0, 1]: the
    average over map pairs of the fraction of cells that differ (0 for fewer than 2)."""
    if len(maps) < 2:
        return 0.0
    stack = np.stack([np.asarray(m) for m in maps]) if _same_shape(maps) else None
    if stack is None:
        raise FitnessError(f'maps differ in shape: {sorted({np.shape(m) for m in maps})}')
    flat = stack.reshape(len(maps), -1)
    distances = [float(np.mean(flat[i] != flat[j]))
                 for i in range(len(maps)) for j in range(i + 1, len(maps))]
    return float(np.mean(distances))


def tpkl_reference_from(tpkls: Sequence[float | None]) -> float:
    """The TPKL reference: the mean of generation 0's finite member TPKLs (nats)."""
    finite = [float(t) for t in tpkls if t is not None and math.isfinite(t)]
    if not finite:
        raise FitnessError('no finite TPKL in generation 0 to use as the reference')
    return float(np.mean(finite))


GENERATION_SUMMARY_METRICS = ('risk_score', 'fault_risk_score', 'collisions', 'fault_collisions',
                              'proximity_time', 'simulation_time')
"""Metrics a generation summary reports as mean_<metric> and best_<metric>."""


def generation_summary(generation: int, breakdowns: Sequence[FitnessBreakdown]
                       ) -> dict[str, Any]:
    """One generation's row for the metrics files.

    ``mean_<metric>``: pooled over every feasible episode of the generation;
    ``best_<metric>``: of the fittest member (ties: lowest index); ``max_risk_score``: the
    highest member mean; also fitness, feasibility, TPKL and diversity aggregates.
    """
    if not breakdowns:
        raise FitnessError(f'generation {generation} has no members to summarise')
    best_member = min(range(len(breakdowns)), key=lambda i: (-breakdowns[i].fitness, i))
    best = breakdowns[best_member]
    episodes = sum(b.episodes for b in breakdowns)
    feasible = sum(b.feasible_episodes for b in breakdowns)
    row: dict[str, Any] = {
        'generation': generation,
        'members': len(breakdowns),
        'episodes': episodes,
        'feasible_fraction': feasible / episodes,
        'mean_fitness': float(np.mean([b.fitness for b in breakdowns])),
        'best_fitness': best.fitness,
        'best_member': best_member,
    }
    for metric in GENERATION_SUMMARY_METRICS:
        pairs = [(getattr(b, metric), b.feasible_episodes) for b in breakdowns
                 if getattr(b, metric) is not None]
        row[f'mean_{metric}'] = (sum(v * n for v, n in pairs) / sum(n for _, n in pairs)
                                 if pairs else None)
        row[f'best_{metric}'] = getattr(best, metric)
    member_risks = [b.risk_score for b in breakdowns if b.risk_score is not None]
    row['max_risk_score'] = max(member_risks) if member_risks else None
    row['mean_risk_score_all'] = (sum(b.risk_score_all * b.episodes for b in breakdowns)
                                  / episodes)
    tpkls = [b.tpkl for b in breakdowns if b.tpkl is not None]
    row['mean_tpkl'] = float(np.mean(tpkls)) if tpkls else None
    row['best_tpkl'] = best.tpkl
    row['tpkl_reference'] = next((b.tpkl_reference for b in breakdowns
                                  if b.tpkl_reference is not None), None)
    diversities = [b.diversity for b in breakdowns if b.diversity is not None]
    row['mean_diversity'] = float(np.mean(diversities)) if diversities else None
    return row


def _episode_values(index: int, episode: EpisodeMetricsLike | Mapping[str, Any]
                    ) -> dict[str, float | bool]:
    """The fields fitness needs, validated; proximity_fraction is derived here."""
    def get(name: str) -> Any:
        if isinstance(episode, Mapping):
            if name not in episode:
                raise FitnessError(f'episode {index} has no {name!r}')
            return episode[name]
        if not hasattr(episode, name):
            raise FitnessError(f'episode {index} ({type(episode).__name__}) has no {name!r}')
        return getattr(episode, name)

    values: dict[str, float | bool] = {'feasible': bool(get('feasible'))}
    for name in ('collisions', 'fault_collisions', 'proximity_time', 'simulation_time',
                 'risk_score', 'fault_risk_score'):
        value = float(get(name))
        require_non_negative(f'episode {index}: {name}', value, FitnessError)
        values[name] = value
    simulation_time = float(values['simulation_time'])
    values['proximity_fraction'] = (min(1.0, float(values['proximity_time']) / simulation_time)
                                    if simulation_time > 0.0 else 0.0)
    return values


def _same_shape(maps: Sequence[np.ndarray]) -> bool:
    return len({np.shape(m) for m in maps}) == 1
