"""Crossover and mutation: whole-tensor inheritance, blending, spread-scaled noise, seeding."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_evolver.errors import GenomeError
from sessgan_evolver.genome import Genome
from sessgan_evolver.genome_operators import OperatorConfig, crossover, mutate, tensor_spread

pytestmark = pytest.mark.unit


@pytest.fixture
def parents(make_state_dict) -> tuple[Genome, Genome]:
    return (Genome.from_state_dict(make_state_dict(seed=1)),
            Genome.from_state_dict(make_state_dict(seed=2)))


def test_uniform_crossover_takes_every_tensor_whole_from_one_parent(parents):
    a, b = parents
    child = crossover(a, b, OperatorConfig(), np.random.default_rng(0))
    sources = []
    for name, tensor in child.items():
        from_a, from_b = torch.equal(tensor, a[name]), torch.equal(tensor, b[name])
        assert from_a or from_b, name
        sources.append('b' if from_b and not from_a else 'a')
    assert 'a' in sources and 'b' in sources  # 24 tensors at p = 0.5


@pytest.mark.parametrize(('probability', 'parent'), [(0.0, 0), (1.0, 1)])
def test_swap_probability_extremes_copy_one_parent(parents, probability, parent):
    config = OperatorConfig(crossover_swap_probability=probability)
    child = crossover(*parents, config, np.random.default_rng(3))
    assert child.equals(parents[parent])


def test_crossover_is_seeded(parents):
    first = crossover(*parents, OperatorConfig(), np.random.default_rng(7))
    second = crossover(*parents, OperatorConfig(), np.random.default_rng(7))
    assert first.equals(second)


def test_blend_crossover_lies_between_the_parents(parents):
    a, b = parents
    child = crossover(a, b, OperatorConfig(blend_crossover=True), np.random.default_rng(0))
    for name, tensor in child.items():
        low, high = torch.minimum(a[name], b[name]), torch.maximum(a[name], b[name])
        assert bool(((tensor >= low - 1e-6) & (tensor <= high + 1e-6)).all()), name


def test_crossover_rejects_incompatible_parents(parents, make_state_dict):
    other = Genome.from_state_dict(make_state_dict(channels=5))
    with pytest.raises(GenomeError):
        crossover(parents[0], other, OperatorConfig(), np.random.default_rng(0))


def test_mutation_noise_is_scaled_to_each_tensors_spread():
    big = torch.randn(200, 50, generator=torch.Generator().manual_seed(0)) * 3.0
    small = big / 100.0
    genome = Genome({'big.weight': big, 'small.weight': small})
    config = OperatorConfig(mutation_scale=0.1, mutation_probability=1.0)
    child = mutate(genome, config, np.random.default_rng(0))
    for name, tensor in genome.items():
        noise_std = float((child[name] - tensor).std())
        expected = 0.1 * float(tensor.std(unbiased=False))
        assert noise_std == pytest.approx(expected, rel=0.05), name


def test_constant_tensors_still_mutate_through_the_floors():
    genome = Genome({'norm.weight': torch.ones(1000), 'conv.bias': torch.zeros(1000)})
    config = OperatorConfig(mutation_scale=0.1, mutation_probability=1.0)
    assert tensor_spread(genome['norm.weight'], config) == pytest.approx(0.1)
    assert tensor_spread(genome['conv.bias'], config) == pytest.approx(1e-3)
    child = mutate(genome, config, np.random.default_rng(0))
    assert float((child['norm.weight'] - 1.0).std()) == pytest.approx(0.1 * 0.1, rel=0.1)
    assert float(child['conv.bias'].std()) == pytest.approx(0.1 * 1e-3, rel=0.1)


def test_mutation_probability_selects_tensors_and_never_none(state_dict):
    genome = Genome.from_state_dict(state_dict)
    child = mutate(genome, OperatorConfig(mutation_probability=0.0), np.random.default_rng(5))
    changed = [name for name, t in child.items() if not torch.equal(t, genome[name])]
    assert len(changed) == 1
    child = mutate(genome, OperatorConfig(mutation_probability=1.0), np.random.default_rng(5))
    assert all(not torch.equal(t, genome[name]) for name, t in child.items())


def test_running_var_stays_positive_under_huge_mutation(state_dict):
    genome = Genome.from_state_dict(state_dict)
    config = OperatorConfig(mutation_scale=50.0, mutation_probability=1.0)
    child = mutate(genome, config, np.random.default_rng(1))
    variances = [t for name, t in child.items() if name.endswith('running_var')]
    assert variances
    assert all(bool((t >= config.min_running_var).all()) for t in variances)
    assert any(bool((t == config.min_running_var).any()) for t in variances)


def test_mutation_is_seeded_and_leaves_its_input_alone(state_dict):
    genome = Genome.from_state_dict(state_dict)
    before = genome.digest()
    first = mutate(genome, OperatorConfig(), np.random.default_rng(11))
    second = mutate(genome, OperatorConfig(), np.random.default_rng(11))
    third = mutate(genome, OperatorConfig(), np.random.default_rng(12))
    assert first.equals(second)
    assert not first.equals(third)
    assert genome.digest() == before


def test_an_explicit_noise_generator_is_used(state_dict):
    genome = Genome.from_state_dict(state_dict)
    config = OperatorConfig(mutation_probability=1.0)
    first = mutate(genome, config, np.random.default_rng(0), torch.Generator().manual_seed(4))
    second = mutate(genome, config, np.random.default_rng(0), torch.Generator().manual_seed(4))
    third = mutate(genome, config, np.random.default_rng(0), torch.Generator().manual_seed(5))
    assert first.equals(second)
    assert not first.equals(third)


@pytest.mark.parametrize('field', [{'mutation_probability': 1.5},
                                   {'crossover_swap_probability': -0.1},
                                   {'mutation_scale': float('nan')},
                                   {'min_running_var': 0.0}])
def test_invalid_operator_config_is_rejected(field):
    with pytest.raises(GenomeError):
        OperatorConfig(**field).validate()
