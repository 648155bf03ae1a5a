"""The TOAD-GAN model: scale shapes, token-aware downsampling, pyramid sampling and state."""

from __future__ import annotations

import pytest
import torch

from sessgan_core.scenarios import get_scenario
from sessgan_gen.downsampling import downsample_pyramid, one_hot, token_aware_downsample
from sessgan_gen.errors import CheckpointError
from sessgan_gen.model import (
    GeneratorPyramid,
    PatchDiscriminator,
    pyramid_from_state_dict,
    pyramid_scale_shapes,
    receptive_field,
    scaled_shapes,
)

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def small_pyramid(num_tokens: int = 3, seed: int = 0) -> GeneratorPyramid:
    torch.manual_seed(seed)
    pyramid = GeneratorPyramid(num_tokens, pyramid_scale_shapes(16, 16), channels=8)
    pyramid.noise_amplitudes.copy_(torch.tensor([1.0, 0.3]))
    return pyramid.eval()


def test_scale_count_grows_with_map_size_and_coarsest_sees_the_layout():
    room = pyramid_scale_shapes(32, 32)
    track = pyramid_scale_shapes(128, 128)
    assert room == [(8, 8), (16, 16), (32, 32)]
    assert track == [(8, 8), (16, 16), (32, 32), (64, 64), (128, 128)]
    for shapes in (room, track):
        assert max(shapes[0]) <= 2 * receptive_field()
        assert shapes == sorted(shapes)


def test_a_scale_limit_keeps_the_finest_scales():
    assert pyramid_scale_shapes(128, 128, max_scales=3) == [(32, 32), (64, 64), (128, 128)]
    assert pyramid_scale_shapes(32, 32, max_scales=3) == pyramid_scale_shapes(32, 32)
    assert pyramid_scale_shapes(128, 128, max_scales=0) == pyramid_scale_shapes(128, 128)
    assert pyramid_scale_shapes(128, 128, max_scales=1) == [(128, 128)]
    with pytest.raises(ValueError, match='max_scales'):
        pyramid_scale_shapes(32, 32, max_scales=-1)


def test_scale_shapes_of_non_square_and_tiny_maps():
    shapes = pyramid_scale_shapes(20, 60)
    assert shapes[-1] == (20, 60)
    assert max(shapes[0]) <= 14
    assert min(shapes[0]) >= receptive_field()  # no side below one receptive field
    assert pyramid_scale_shapes(5, 5) == [(5, 5)]
    with pytest.raises(ValueError):
        pyramid_scale_shapes(32, 32, scale_factor=1.5)


def test_downsampling_keeps_a_one_cell_wall_and_a_thin_track():
    factory = get_scenario('factory')
    cells = torch.zeros(32, 32, dtype=torch.long)
    cells[:, 13] = 1  # a one-cell wall
    shapes = [(8, 8), (16, 16), (32, 32)]
    small = downsample_pyramid(one_hot(cells, 2), shapes, factory.hierarchy)[0]
    assert torch.allclose(small.sum(dim=1), torch.ones(1, 8, 8))
    tokens = small.argmax(dim=1)[0]
    assert (tokens[:, 3] == 1).all()  # the wall survives a factor-4 reduction
    assert (tokens[:, :3] == 0).all() and (tokens[:, 4:] == 0).all()
    half = token_aware_downsample(one_hot(cells, 2), (16, 16), factory.hierarchy)
    assert (half.argmax(dim=1)[0, :, 6] == 1).all()  # covers half of each 2x2 block: kept
    speck = torch.zeros(32, 32, dtype=torch.long)
    speck[9, 9] = 1  # a single wall cell covers a quarter of its block: the majority wins
    assert (token_aware_downsample(one_hot(speck, 2), (16, 16), factory.hierarchy)
            .argmax(dim=1) == 0).all()
    assert small.max() > 0.99  # sharp softmax: nearly one-hot

    racetrack = get_scenario('racetrack')
    track = torch.ones(64, 64, dtype=torch.long)  # all out of bounds ...
    track[30, :] = 0  # ... but one row of track, which outranks O in the hierarchy
    shapes = [(8, 8), (16, 16), (32, 32), (64, 64)]
    pyramid = downsample_pyramid(one_hot(track, 2), shapes, racetrack.hierarchy)
    assert [tuple(p.shape[-2:]) for p in pyramid] == shapes
    assert torch.equal(pyramid[-1], one_hot(track, 2))
    for scaled in pyramid:
        assert (scaled.argmax(dim=1) == 0).any(dim=-1).sum() >= 1


def test_sample_shapes_range_and_any_size():
    pyramid = small_pyramid()
    maps = pyramid.sample(batch=4)
    assert maps.shape == (4, 16, 16) and maps.dtype == torch.int64
    assert int(maps.min()) >= 0 and int(maps.max()) < 3
    assert pyramid.sample(seeds=[1, 2], size=(24, 40)).shape == (2, 24, 40)
    assert scaled_shapes(pyramid.scale_shapes, (32, 32)) == [(16, 16), (32, 32)]
    assert pyramid.sample(batch=0).shape == (0, 16, 16)


def test_same_seed_same_map_alone_or_in_any_batch():
    pyramid = small_pyramid()
    seeds = list(range(40, 60))
    batch = pyramid.sample(seeds=seeds)
    for index in (0, 7, 19):
        assert torch.equal(pyramid.sample(seeds=[seeds[index]])[0], batch[index])
    shuffled = pyramid.sample(seeds=seeds[::-1])
    assert torch.equal(shuffled.flip(0), batch)
    assert not torch.equal(batch[0], batch[1])  # different seeds, different noise


def test_sampling_uses_eval_mode_and_restores_the_mode():
    pyramid = small_pyramid()
    pyramid.train()
    before = {k: v.clone() for k, v in pyramid.state_dict().items()}
    first = pyramid.sample(seeds=[3])
    assert pyramid.training  # mode restored
    for key, value in pyramid.state_dict().items():
        assert torch.equal(value, before[key]), f'{key} changed by sampling'
    assert torch.equal(first, pyramid.sample(seeds=[3]))


def test_generator_gives_noise_to_every_cell_and_discriminator_scores_patches():
    pyramid = small_pyramid()
    noises = pyramid.draw_noise(torch.Generator().manual_seed(0), batch=2)
    assert [tuple(n.shape) for n in noises] == [(2, 3, 8, 8), (2, 3, 16, 16)]
    output = pyramid.generate(noises)
    assert output.shape == (2, 3, 16, 16)
    # Every scale outputs a distribution over tokens per cell, like the real maps.
    assert torch.allclose(output.sum(dim=1), torch.ones(2, 16, 16), atol=1e-5)
    critic = PatchDiscriminator(3, 8)
    assert critic(output).shape == (2, 1, 16, 16)


def test_state_dict_holds_generators_and_the_two_noise_buffers_only():
    pyramid = small_pyramid()
    keys = list(pyramid.state_dict())
    assert 'noise_amplitudes' in keys and 'reconstruction_noise' in keys
    others = [k for k in keys if k not in ('noise_amplitudes', 'reconstruction_noise')]
    assert all(k.startswith('generators.') for k in others)
    assert any(k.endswith('running_var') for k in others)  # BatchNorm statistics included
    genome = pyramid.genome_names()
    assert 'noise_amplitudes' not in genome and 'reconstruction_noise' not in genome
    assert not any(k.endswith('num_batches_tracked') for k in genome)
    assert any(k.endswith('running_mean') for k in genome)


def test_state_dict_round_trip_gives_identical_maps():
    pyramid = small_pyramid(seed=1)
    clone = pyramid_from_state_dict(pyramid.state_dict(), pyramid.scale_shapes)
    assert clone.num_tokens == 3 and clone.channels == 8
    assert torch.equal(clone.sample(seeds=[5, 6]), pyramid.sample(seeds=[5, 6]))
    assert torch.equal(clone.reconstruct(), pyramid.reconstruct())


@pytest.mark.parametrize('change, message', [
    (lambda sd: sd.pop('generators.1.tail.bias'), "lack key 'generators.1.tail.bias'"),
    (lambda sd: sd.__setitem__('extra.weight', torch.zeros(1)), "unexpected key 'extra.weight'"),
    (lambda sd: sd.__setitem__('generators.0.head.conv.weight', torch.zeros(8, 2, 3, 3)),
     "'generators.0.head.conv.weight' has shape (8, 2, 3, 3), expected (8, 3, 3, 3)"),
    (lambda sd: sd['generators.0.body.norm.running_var'].fill_(float('nan')),
     "'generators.0.body.norm.running_var' contains NaN"),
    (lambda sd: sd.__setitem__('noise_amplitudes', [1.0, 0.3]), "'noise_amplitudes' is a list"),
])
def test_load_state_dict_names_the_bad_key(change, message):
    pyramid = small_pyramid()
    state = {k: v.clone() for k, v in pyramid.state_dict().items()}
    change(state)
    with pytest.raises(CheckpointError) as caught:
        small_pyramid().load_state_dict(state)
    assert message in str(caught.value)


def test_pyramid_from_state_dict_rejects_foreign_weights():
    with pytest.raises(CheckpointError, match='generators.0.head.conv.weight'):
        pyramid_from_state_dict({'weight': torch.zeros(3)}, [(8, 8)])
    pyramid = small_pyramid()
    with pytest.raises(CheckpointError, match='generators.2'):
        pyramid_from_state_dict(pyramid.state_dict(), [(8, 8), (12, 12), (16, 16)])
