"""The fitness formula, its terms, diversity and the generation summary."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from sessgan_evolver.errors import FitnessError
from sessgan_evolver.fitness import (
    FitnessConfig,
    generation_summary,
    map_diversity,
    member_fitness,
    tpkl_reference_from,
)

pytestmark = pytest.mark.unit


@dataclass
class Episode:
    collisions: int
    proximity_time: float
    simulation_time: float
    feasible: bool = True
    agent_caused: int = 0
    """Collisions of an agent driving into the standing robot: not faults."""

    @property
    def risk_score(self) -> float:
        return self.collisions * self.proximity_time / self.simulation_time

    @property
    def fault_collisions(self) -> int:
        return self.collisions - self.agent_caused

    @property
    def fault_risk_score(self) -> float:
        return self.fault_collisions * self.proximity_time / self.simulation_time


def test_formula_by_hand():
    episodes = [Episode(2, 3.0, 10.0), Episode(0, 5.0, 20.0), Episode(4, 8.0, 8.0, False)]
    config = FitnessConfig(risk_weight=1.0, proximity_weight=0.1, infeasible_weight=1.0,
                           tpkl_weight=2.0, diversity_weight=0.5)
    result = member_fitness(episodes, tpkl=0.3, tpkl_reference=0.2, diversity=0.4,
                            config=config)
    risk = (0.6 + 0.0) / 2
    proximity = (0.3 + 0.25) / 2
    expected = risk + 0.1 * proximity - 1 / 3 - 2.0 * (0.3 / 0.2 - 1) + 0.5 * 0.4
    assert result.fitness == pytest.approx(expected)
    assert result.risk_score == pytest.approx(0.3)
    assert result.risk_score_all == pytest.approx((0.6 + 0.0 + 4.0) / 3)
    assert result.feasible_episodes == 2 and result.feasible_fraction == pytest.approx(2 / 3)
    assert result.collisions == pytest.approx(1.0)
    assert result.proximity_time == pytest.approx(4.0)
    assert result.simulation_time == pytest.approx(15.0)
    assert result.tpkl_ratio == pytest.approx(1.5)
    assert result.tpkl_penalty == pytest.approx(1.0)
    assert result.diversity_bonus == pytest.approx(0.2)
    row = result.as_row()
    assert row['fitness'] == result.fitness and row['tpkl'] == 0.3


def test_no_feasible_map_scores_zero_risk_and_the_full_penalty():
    result = member_fitness([Episode(3, 5.0, 10.0, False)] * 3)
    assert result.risk_score is None and result.collisions is None
    assert result.risk_term == 0.0 and result.proximity_term == 0.0
    assert result.fitness == pytest.approx(-1.0)


def test_proximity_shaping_ranks_near_misses_above_clean_runs():
    clean = member_fitness([Episode(0, 0.0, 30.0)] * 3)
    near_miss = member_fitness([Episode(0, 6.0, 30.0)] * 3)
    assert clean.risk_score == near_miss.risk_score == 0.0
    assert near_miss.fitness > clean.fitness
    unshaped = FitnessConfig(proximity_weight=0.0)
    assert member_fitness([Episode(0, 6.0, 30.0)], config=unshaped).fitness == 0.0


def test_tpkl_penalty_only_above_the_reference_and_tolerance():
    episodes = [Episode(1, 1.0, 10.0)]
    assert member_fitness(episodes, tpkl=0.1, tpkl_reference=0.2).tpkl_penalty == 0.0
    assert member_fitness(episodes, tpkl=0.2, tpkl_reference=0.2).tpkl_penalty == 0.0
    assert member_fitness(episodes, tpkl=0.3, tpkl_reference=0.2).tpkl_penalty == \
        pytest.approx(0.5)
    tolerant = FitnessConfig(tpkl_tolerance=0.6)
    assert member_fitness(episodes, tpkl=0.3, tpkl_reference=0.2,
                          config=tolerant).tpkl_penalty == 0.0
    assert member_fitness(episodes, tpkl=0.3).tpkl_penalty == 0.0  # no reference yet


def test_mappings_are_accepted_as_episodes():
    row = {'collisions': 1, 'proximity_time': 2.0, 'simulation_time': 4.0,
           'risk_score': 0.5, 'fault_collisions': 1, 'fault_risk_score': 0.5,
           'feasible': True, 'outcome': 'collision_limit'}
    assert member_fitness([row]).risk_score == 0.5


def test_collisions_the_robot_did_not_cause_earn_no_fitness():
    rammed = member_fitness([Episode(2, 3.0, 10.0, agent_caused=2)],
                            config=FitnessConfig(proximity_weight=0.0, diversity_weight=0.0))
    assert rammed.risk_score == pytest.approx(0.6)  # the paper's figure, still reported
    assert rammed.fault_risk_score == 0.0 and rammed.fitness == 0.0
    own = member_fitness([Episode(2, 3.0, 10.0, agent_caused=1)],
                         config=FitnessConfig(proximity_weight=0.0, diversity_weight=0.0))
    assert own.fitness == pytest.approx(0.3) and own.fault_collisions == 1


@pytest.mark.parametrize('episode', [
    {'collisions': 1, 'proximity_time': 2.0, 'simulation_time': 4.0, 'feasible': True,
     'fault_collisions': 1, 'fault_risk_score': 0.5},
    {'collisions': 1, 'proximity_time': -2.0, 'simulation_time': 4.0, 'risk_score': 0.0,
     'fault_collisions': 1, 'fault_risk_score': 0.0, 'feasible': True},
    {'collisions': 1, 'proximity_time': float('nan'), 'simulation_time': 4.0,
     'risk_score': 0.0, 'fault_collisions': 1, 'fault_risk_score': 0.0, 'feasible': True},
])
def test_bad_episodes_are_rejected(episode):
    with pytest.raises(FitnessError):
        member_fitness([episode])


def test_bad_inputs_are_rejected():
    with pytest.raises(FitnessError):
        member_fitness([])
    with pytest.raises(FitnessError):
        member_fitness([Episode(0, 0.0, 1.0)], diversity=1.5)
    with pytest.raises(FitnessError):
        member_fitness([Episode(0, 0.0, 1.0)], tpkl=float('inf'), tpkl_reference=1.0)
    with pytest.raises(FitnessError):
        member_fitness([Episode(0, 0.0, 1.0)], config=FitnessConfig(risk_weight=-1.0))


def test_map_diversity_is_the_mean_pairwise_hamming_fraction():
    zeros, ones = np.zeros((4, 4), np.int8), np.ones((4, 4), np.int8)
    half = np.zeros((4, 4), np.int8)
    half[:2] = 1
    assert map_diversity([zeros]) == 0.0
    assert map_diversity([zeros, zeros]) == 0.0
    assert map_diversity([zeros, ones]) == 1.0
    assert map_diversity([zeros, ones, half]) == pytest.approx((1.0 + 0.5 + 0.5) / 3)
    with pytest.raises(FitnessError):
        map_diversity([zeros, np.zeros((3, 4))])


def test_tpkl_reference_is_the_mean_of_finite_values():
    assert tpkl_reference_from([0.1, None, 0.3, float('nan')]) == pytest.approx(0.2)
    with pytest.raises(FitnessError):
        tpkl_reference_from([None])


def test_generation_summary_pools_feasible_episodes_and_reports_the_fittest():
    strong = member_fitness([Episode(2, 5.0, 10.0), Episode(0, 0.0, 10.0, False)],
                            tpkl=0.2, tpkl_reference=0.2, diversity=0.5)
    weak = member_fitness([Episode(0, 1.0, 20.0), Episode(0, 1.0, 30.0)],
                          tpkl=0.4, tpkl_reference=0.2, diversity=0.1)
    row = generation_summary(4, [weak, strong])
    assert row['generation'] == 4 and row['members'] == 2 and row['episodes'] == 4
    assert row['best_member'] == 1 and row['best_fitness'] == strong.fitness
    assert row['feasible_fraction'] == pytest.approx(0.75)
    # Pooled over the 3 feasible episodes: risks 1.0, 0, 0.
    assert row['mean_risk_score'] == pytest.approx(1.0 / 3)
    assert row['mean_simulation_time'] == pytest.approx((10.0 + 20.0 + 30.0) / 3)
    assert row['best_risk_score'] == pytest.approx(1.0)
    assert row['max_risk_score'] == pytest.approx(1.0)
    assert row['mean_tpkl'] == pytest.approx(0.3) and row['tpkl_reference'] == 0.2
    assert row['mean_diversity'] == pytest.approx(0.3)
