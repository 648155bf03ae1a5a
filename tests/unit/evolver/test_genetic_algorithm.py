"""The ask/tell genetic algorithm: generation 0, elitism, selection, state, determinism."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
import torch

from sessgan_evolver.algorithm import GeneticAlgorithm, GeneticAlgorithmConfig
from sessgan_evolver.errors import AlgorithmStateError
from sessgan_evolver.genome import Genome
from sessgan_evolver.genome_operators import OperatorConfig
from sessgan_evolver.seeding import SeedStream, shared_seeds

pytestmark = pytest.mark.unit


def toy_fitness(genome: Genome, generation_seed: int) -> float:
    """A deterministic stand-in for simulation: the tail weights' sum plus seeded noise."""
    value = float(sum(t.sum() for name, t in genome.items() if 'tail.weight' in name))
    return value + 0.001 * float(np.random.default_rng(generation_seed).normal())


def run(seed: int, generations: int, initial: Genome, population: int = 6
        ) -> tuple[list[list[str]], list[list[float]], GeneticAlgorithm]:
    config = GeneticAlgorithmConfig(population_size=population, elite_count=1, seed=seed)
    algorithm = GeneticAlgorithm(config, initial)
    digests, fitnesses = [], []
    for _ in range(generations):
        genomes = algorithm.ask()
        [map_seed] = shared_seeds(seed, algorithm.generation, 1)
        values = [toy_fitness(genome, map_seed) for genome in genomes]
        digests.append([genome.digest() for genome in genomes])
        fitnesses.append(values)
        algorithm.tell(values)
    return digests, fitnesses, algorithm


@pytest.fixture
def initial(state_dict) -> Genome:
    return Genome.from_state_dict(state_dict)


def test_generation_zero_is_mutated_copies_of_the_pretrained_genome(initial):
    algorithm = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=5), initial)
    population = algorithm.ask()
    assert algorithm.generation == 0 and len(population) == 5
    assert population[0].equals(initial)
    assert [origin.kind for origin in algorithm.origins] == ['original'] + ['initial'] * 4
    digests = {genome.digest() for genome in population}
    assert len(digests) == 5
    unmutated = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=3,
                                                        keep_original=False), initial)
    assert not any(genome.equals(initial) for genome in unmutated.ask())


def test_ask_is_repeatable_until_tell(initial):
    algorithm = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=4), initial)
    assert [g.digest() for g in algorithm.ask()] == [g.digest() for g in algorithm.ask()]


def test_elites_are_kept_unchanged_and_first(initial):
    config = GeneticAlgorithmConfig(population_size=6, elite_count=2)
    algorithm = GeneticAlgorithm(config, initial)
    population = algorithm.ask()
    result = algorithm.tell([0.1, 0.5, 0.3, 0.9, -math.inf, 0.2])
    assert result.ranking[:2] == (3, 1) and result.elite_members == (3, 1)
    assert result.best_member == 3 and result.best_fitness == 0.9
    following = algorithm.ask()
    assert following[0].equals(population[3]) and following[1].equals(population[1])
    assert [o.kind for o in algorithm.origins[:2]] == ['elite', 'elite']
    assert all(o.kind == 'offspring' for o in algorithm.origins[2:])
    assert algorithm.generation == 1
    assert algorithm.best is not None and algorithm.best.genome.equals(population[3])


def test_tournament_selection_prefers_fitter_parents(initial):
    config = GeneticAlgorithmConfig(population_size=20, elite_count=0, tournament_size=3,
                                    crossover_probability=0.0)
    algorithm = GeneticAlgorithm(config, initial)
    algorithm.tell([float(i) for i in range(20)])
    parents = [origin.parents[0] for origin in algorithm.origins]
    # A 3-way tournament picks the top half of the ranking with probability 7/8.
    assert np.mean(parents) > 12


def test_crossover_children_name_two_parents(initial):
    config = GeneticAlgorithmConfig(population_size=8, crossover_probability=1.0)
    algorithm = GeneticAlgorithm(config, initial)
    algorithm.tell([float(i) for i in range(8)])
    assert all(len(o.parents) == 2 for o in algorithm.origins if o.kind == 'offspring')


def test_tell_one_in_any_order_equals_tell(initial):
    values = [0.3, 0.1, 0.7, 0.2, 0.5]
    config = GeneticAlgorithmConfig(population_size=5, seed=4)
    whole = GeneticAlgorithm(config, initial)
    whole.tell(values)
    piecewise = GeneticAlgorithm(config, initial)
    results = [piecewise.tell_one(member, values[member]) for member in (4, 0, 2, 1)]
    assert results == [None] * 4 and piecewise.pending_members() == [3]
    assert piecewise.fitnesses[2] == 0.7
    final = piecewise.tell_one(3, values[3])
    assert final is not None and final.generation == 0 and final.fitnesses == tuple(values)
    assert [g.digest() for g in piecewise.ask()] == [g.digest() for g in whole.ask()]


def test_tell_misuse_is_reported(initial):
    algorithm = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=3), initial)
    with pytest.raises(AlgorithmStateError, match='expects 3'):
        algorithm.tell([1.0, 2.0])
    with pytest.raises(AlgorithmStateError, match='not allowed'):
        algorithm.tell([1.0, math.nan, 2.0])
    with pytest.raises(AlgorithmStateError, match='not allowed'):
        algorithm.tell_one(0, math.inf)
    algorithm.tell_one(1, 0.5)
    with pytest.raises(AlgorithmStateError, match='already told'):
        algorithm.tell_one(1, 0.6)
    with pytest.raises(AlgorithmStateError, match='tell_one'):
        algorithm.tell([1.0, 2.0, 3.0])
    with pytest.raises(AlgorithmStateError, match='outside'):
        algorithm.tell_one(3, 1.0)


@pytest.mark.parametrize('config', [
    GeneticAlgorithmConfig(population_size=0),
    GeneticAlgorithmConfig(population_size=3, elite_count=4),
    GeneticAlgorithmConfig(tournament_size=0),
    GeneticAlgorithmConfig(crossover_probability=2.0),
    GeneticAlgorithmConfig(operators=OperatorConfig(mutation_probability=-1.0)),
])
def test_invalid_config_is_rejected(config, initial):
    with pytest.raises(AlgorithmStateError):
        GeneticAlgorithm(config, initial)


def test_same_seed_gives_identical_generations_and_fitnesses(initial):
    digests_a, fitnesses_a, _ = run(seed=3, generations=5, initial=initial)
    digests_b, fitnesses_b, _ = run(seed=3, generations=5, initial=initial)
    assert digests_a == digests_b
    assert fitnesses_a == fitnesses_b
    digests_c, _, _ = run(seed=4, generations=5, initial=initial)
    assert digests_c[1:] != digests_a[1:]


def test_state_dict_round_trip_continues_identically(initial):
    _, fitnesses_full, full = run(seed=9, generations=6, initial=initial)
    _, _, first_half = run(seed=9, generations=3, initial=initial)
    buffer = io.BytesIO()
    torch.save(first_half.state_dict(), buffer)
    buffer.seek(0)
    restored = GeneticAlgorithm.from_state_dict(torch.load(buffer, weights_only=True))
    assert restored.generation == 3
    for _ in range(3):
        [map_seed] = shared_seeds(9, restored.generation, 1)
        restored.tell([toy_fitness(g, map_seed) for g in restored.ask()])
    assert [g.digest() for g in restored.ask()] == [g.digest() for g in full.ask()]
    assert restored.history == full.history
    assert [h['best_fitness'] for h in full.history] == [max(f) for f in fitnesses_full]
    assert restored.best.genome.equals(full.best.genome)


def test_state_dict_with_partial_tells_is_restored(initial):
    algorithm = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=3), initial)
    algorithm.tell_one(2, 0.25)
    restored = GeneticAlgorithm.from_state_dict(algorithm.state_dict())
    assert restored.fitnesses == [None, None, 0.25]
    assert restored.pending_members() == [0, 1]


def test_from_state_dict_rejects_foreign_or_broken_state(initial):
    with pytest.raises(AlgorithmStateError, match='format'):
        GeneticAlgorithm.from_state_dict({'generation': 0})
    state = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=3), initial).state_dict()
    del state['population'][1]
    with pytest.raises(AlgorithmStateError, match='members'):
        GeneticAlgorithm.from_state_dict(state)
    state = GeneticAlgorithm(GeneticAlgorithmConfig(population_size=3), initial).state_dict()
    del state['rng_state']
    with pytest.raises(AlgorithmStateError, match='rng_state'):
        GeneticAlgorithm.from_state_dict(state)


def test_shared_seeds_depend_only_on_campaign_seed_generation_and_stream():
    assert shared_seeds(1, 2, 3) == shared_seeds(1, 2, 3)
    assert shared_seeds(1, 2, 3) != shared_seeds(1, 3, 3)
    assert shared_seeds(1, 2, 3) != shared_seeds(1, 2, 3, SeedStream.SIMULATION)
    assert shared_seeds(1, 2, 5)[:3] == shared_seeds(1, 2, 3)
    assert all(0 <= s < 2**32 for s in shared_seeds(7, 0, 10))
    with pytest.raises(ValueError):
        shared_seeds(-1, 0, 1)
