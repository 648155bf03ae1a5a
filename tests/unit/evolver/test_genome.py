"""Genome: which entries evolve, state-dict round trips, bytes, variance clamping."""

from __future__ import annotations

import pytest
import torch

from sessgan_evolver.errors import GenomeError
from sessgan_evolver.genome import Genome, clamp_positive, is_evolvable_entry
from sessgan_gen.model import GeneratorPyramid

pytestmark = pytest.mark.unit


def test_default_rule_keeps_weights_and_batchnorm_statistics_only(state_dict):
    genome = Genome.from_state_dict(state_dict)
    names = genome.names()
    assert 'generators.0.head.conv.weight' in names
    assert 'generators.1.body.norm.running_var' in names
    assert 'generators.0.tail.bias' in names
    assert not any(name.endswith('num_batches_tracked') for name in names)
    assert 'noise_amplitudes' not in names
    assert 'reconstruction_noise' not in names
    # State-dict order is kept.
    assert names == [name for name in state_dict if name in set(names)]


def test_default_rule_matches_the_real_pyramid_genome_names():
    pyramid = GeneratorPyramid(2, [(8, 8), (16, 16)], channels=4)
    assert Genome.from_state_dict(pyramid.state_dict()).names() == pyramid.genome_names()


def test_a_custom_predicate_overrides_the_rule(state_dict):
    def only_convolutions(name: str, tensor: torch.Tensor) -> bool:
        return tensor.is_floating_point() and '.conv.' in name

    genome = Genome.from_state_dict(state_dict, is_evolvable=only_convolutions)
    assert genome.names() and all('.conv.' in name for name in genome.names())
    assert not is_evolvable_entry('generators.0.head.norm.num_batches_tracked',
                                  torch.tensor(3))


def test_to_state_dict_substitutes_genes_and_keeps_fixed_buffers(state_dict):
    genome = Genome.from_state_dict(state_dict)
    changed = Genome({name: t + 1.0 for name, t in genome.items()})
    merged = changed.to_state_dict(state_dict)
    assert list(merged) == list(state_dict)
    assert torch.equal(merged['generators.0.head.conv.weight'],
                       state_dict['generators.0.head.conv.weight'] + 1.0)
    assert torch.equal(merged['noise_amplitudes'], state_dict['noise_amplitudes'])
    assert merged['generators.0.head.norm.num_batches_tracked'].item() == 100


def test_to_state_dict_loads_into_the_real_pyramid():
    pyramid = GeneratorPyramid(2, [(8, 8), (16, 16)], channels=4)
    template = pyramid.state_dict()
    genome = Genome.from_state_dict(template)
    doubled = Genome({name: t * 2.0 for name, t in genome.items()})
    fresh = GeneratorPyramid(2, [(8, 8), (16, 16)], channels=4)
    fresh.load_state_dict(doubled.to_state_dict(template))
    assert torch.equal(fresh.generators[0].tail.weight, pyramid.generators[0].tail.weight * 2)


def test_to_state_dict_rejects_a_shape_mismatch(state_dict):
    genome = Genome.from_state_dict(state_dict)
    name = 'generators.0.tail.bias'
    broken = Genome({**genome.tensors, name: torch.zeros(7)})
    with pytest.raises(GenomeError, match='tail.bias'):
        broken.to_state_dict(state_dict)


def test_bytes_round_trip_is_exact(state_dict):
    genome = Genome.from_state_dict(state_dict)
    data = genome.to_bytes()
    assert isinstance(data, bytes)
    restored = Genome.from_bytes(bytearray(data))
    assert restored.equals(genome)
    assert restored.digest() == genome.digest()
    assert restored.names() == genome.names()


@pytest.mark.parametrize('data', [b'', b'not a genome at all'])
def test_from_bytes_rejects_garbage(data):
    with pytest.raises(GenomeError):
        Genome.from_bytes(data)


def test_from_bytes_rejects_other_torch_payloads():
    import io
    buffer = io.BytesIO()
    torch.save({'weight': torch.ones(2)}, buffer)
    with pytest.raises(GenomeError, match='not a serialized genome'):
        Genome.from_bytes(buffer.getvalue())


def test_integer_tensors_cannot_be_genes():
    with pytest.raises(GenomeError, match='floating-point'):
        Genome({'counter': torch.tensor(3)})


def test_clamp_positive_only_touches_variances(state_dict):
    genome = Genome.from_state_dict(state_dict)
    negative = Genome({name: t - 10.0 for name, t in genome.items()})
    clamped = clamp_positive(negative, 1e-5)
    for name, tensor in clamped.items():
        if name.endswith('running_var'):
            assert bool((tensor >= 1e-5).all())
        else:
            assert torch.equal(tensor, negative[name])


def test_digest_differs_when_one_value_changes(state_dict):
    genome = Genome.from_state_dict(state_dict)
    other = genome.clone()
    other['generators.0.tail.bias'][0] += 1e-6
    assert other.digest() != genome.digest()
    assert not other.equals(genome)
