"""The baselines' ask/tell: seeded, elites kept without a re-run, latent generation 0 is
random sampling of the generator."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_core.valid_tests import make_environment
from sessgan_evolver.search_methods import (
    METHODS,
    Evaluated,
    GAConfig,
    GridGA,
    LatentEvolution,
    RandomSampling,
    SearchMethodError,
    make_baseline,
)
from sessgan_gen.checkpoint import default_checkpoint_path, load_checkpoint
from sessgan_gen.sampling import sample_token_maps

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def fake_results(proposals, risks):
    """Results without simulation: a feasible episode with the given risk."""
    results = []
    for proposal, risk in zip(proposals, risks):
        environment = make_environment(proposal.cells, 'factory', 'x')
        results.append(Evaluated(proposal, environment, {
            'feasible': True, 'collisions': 1, 'fault_collisions': 1, 'proximity_time': 1.0,
            'simulation_time': 10.0, 'risk_score': float(risk),
            'fault_risk_score': float(risk), 'outcome': 'stuck'}))
    return results


def test_random_sampling_is_seeded_and_samples_the_generator():
    first = RandomSampling('factory', seed=3, batch=4).ask()
    again = RandomSampling('factory', seed=3, batch=4).ask()
    other = RandomSampling('factory', seed=4, batch=4).ask()
    assert [p.map_seed for p in first] == [p.map_seed for p in again]
    assert [p.map_seed for p in first] != [p.map_seed for p in other]
    pyramid, _ = load_checkpoint(default_checkpoint_path('factory'))
    assert np.array_equal(sample_token_maps(pyramid, [first[0].map_seed])[0], first[0].cells)


def test_generator_methods_serve_race_tracks_as_the_sampler_does():
    # The racetrack scenario's track_cleanup: random sampling and the shipped generator of a
    # fresh-seed evaluation give the maps a campaign's generator node serves.
    from sessgan_core.token_map import tokens_to_occupancy
    from sessgan_evolver.fresh_seed import PyramidSource
    from sessgan_gen.environment_sampler import EnvironmentSampler

    proposal = RandomSampling('racetrack', seed=3, batch=1).ask()[0]
    served = EnvironmentSampler().sample([proposal.map_seed], scenario='racetrack')[0]
    assert (tokens_to_occupancy(proposal.cells, 'racetrack') == served.occupancy).all()
    fresh = PyramidSource('shipped', 'racetrack').maps([proposal.map_seed])[0]
    assert (fresh == proposal.cells).all()


@pytest.mark.parametrize('method', ['grid_ga', 'latent'])
def test_genetic_algorithms_keep_their_elite_and_breed_the_rest(method):
    config = GAConfig(population=5, elite_count=1)
    search = make_baseline(method, 'factory', 7, ga_config=config)
    assert search.name == method
    generation0 = search.ask()
    assert len(generation0) == 5 and all(p.origin.startswith('generation 0') for p in
                                         generation0)
    risks = [0.1, 3.0, 0.2, 0.3, 0.4]
    search.tell(fake_results(generation0, risks))
    generation1 = search.ask()
    # The elite (member 1) is not asked again; four children are.
    assert len(generation1) == 4 and all(p.origin.startswith('generation 1') for p in
                                         generation1)
    assert search.population[0].fitness is not None and search.generation == 1
    assert np.array_equal(search.express([search.population[0].genotype])[0],
                          generation0[1].cells)
    replay = make_baseline(method, 'factory', 7, ga_config=config)
    replay.tell(fake_results(replay.ask(), risks))
    assert all(np.array_equal(a.cells, b.cells) and a.sim_seed == b.sim_seed
               for a, b in zip(replay.ask(), generation1))
    with pytest.raises(SearchMethodError, match='told 2 results'):
        search.tell(fake_results(generation1[:2], [0, 0]))


def test_latent_generation_zero_is_random_sampling():
    search = LatentEvolution('factory', 2, GAConfig(population=3))
    pyramid, _ = load_checkpoint(default_checkpoint_path('factory'))
    for proposal in search.ask():
        assert np.array_equal(sample_token_maps(pyramid, [proposal.map_seed])[0],
                              proposal.cells)


def test_grid_ga_starts_from_the_cellular_automaton_and_unknown_names_are_refused():
    search = GridGA('factory', 1, GAConfig(population=2))
    proposal = search.ask()[0]
    assert np.array_equal(proposal.cells, search.automaton.one(proposal.map_seed))
    assert set(METHODS) == {'sessgan', 'random', 'grid_ga', 'cellular_automaton', 'latent',
                            'screened'}
    with pytest.raises(SearchMethodError, match='known'):
        make_baseline('sessgan', 'factory', 0)
    with pytest.raises(SearchMethodError, match='population'):
        GAConfig(population=1).validate()
