"""Sampling many maps: seeds, batch-size independence, sizes, devices."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_gen.model import GeneratorPyramid, pyramid_scale_shapes
from sessgan_gen.sampling import batch_size_for, sample_one, sample_seeds, sample_token_maps
from sessgan_gen.seeding import derive_seeds

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


@pytest.fixture(scope='module')
def pyramid() -> GeneratorPyramid:
    torch.manual_seed(2)
    pyramid = GeneratorPyramid(3, pyramid_scale_shapes(32, 32), channels=8)
    pyramid.noise_amplitudes.copy_(torch.tensor([1.0, 0.2, 0.2]))
    return pyramid.eval()


def test_map_i_depends_only_on_seed_i_whatever_the_batch_size(pyramid):
    seeds = sample_seeds(11, 37)
    whole = sample_token_maps(pyramid, seeds, batch_size=37)
    assert whole.shape == (37, 32, 32) and whole.dtype == np.int64
    for batch_size in (1, 5, 16):
        assert np.array_equal(sample_token_maps(pyramid, seeds, batch_size=batch_size), whole)
    assert np.array_equal(sample_one(pyramid, seeds[20]), whole[20])
    # a member of another generation sharing some seeds gets the same maps for them
    assert np.array_equal(sample_token_maps(pyramid, seeds[30:] + [5])[:7], whole[30:])


def test_seeds_are_reproducible_and_distinct():
    assert sample_seeds(3, 5) == sample_seeds(3, 5)
    assert sample_seeds(3, 5) != sample_seeds(4, 5)
    assert len(set(sample_seeds(3, 1000))) == 1000
    assert derive_seeds(3, 4, stream=0) != derive_seeds(3, 4, stream=1)
    assert all(0 <= seed < 2**63 for seed in sample_seeds(-7, 10))


def test_maps_of_other_sizes_and_the_empty_request(pyramid):
    maps = sample_token_maps(pyramid, [1, 2, 3], size=(48, 20))
    assert maps.shape == (3, 48, 20)
    assert sample_token_maps(pyramid, [], size=(8, 8)).shape == (0, 8, 8)
    assert batch_size_for((32, 32)) == 32 and batch_size_for((128, 128)) == 2
    assert batch_size_for((4096, 4096)) == 1
    with pytest.raises(ValueError):
        sample_token_maps(pyramid, [1], batch_size=0)


def test_global_generator_and_explicit_generator_sampling(pyramid):
    first = pyramid.sample(batch=3, generator=torch.Generator().manual_seed(9))
    again = pyramid.sample(batch=3, generator=torch.Generator().manual_seed(9))
    assert torch.equal(first, again)
    with pytest.raises(ValueError, match='differs'):
        pyramid.sample(batch=2, seeds=[1, 2, 3])


@pytest.mark.skipif(not torch.cuda.is_available(), reason='no CUDA device')
def test_cuda_sampling_matches_cpu(pyramid):
    on_gpu = GeneratorPyramid(3, pyramid.scale_shapes, channels=8)
    on_gpu.load_state_dict(pyramid.state_dict())
    on_gpu = on_gpu.to('cuda').eval()
    cpu = pyramid.sample(seeds=range(20))
    gpu = on_gpu.sample(seeds=range(20))
    assert gpu.device.type == 'cpu'
    assert (cpu == gpu).float().mean() > 0.99  # float differences may flip near-ties


def test_explicit_noise_maps_reproduce_seeded_sampling(pyramid):
    from sessgan_gen.sampling import noise_shapes, sample_token_maps_from_noise, seed_noise_maps

    seeds = [4, 77, 1234]
    noises = [seed_noise_maps(pyramid, seed) for seed in seeds]
    assert [n.shape for n in noises[0]] == noise_shapes(pyramid) == [(3, 8, 8), (3, 16, 16),
                                                                     (3, 32, 32)]
    assert np.array_equal(sample_token_maps_from_noise(pyramid, noises),
                          sample_token_maps(pyramid, seeds))
    # Other sizes scale every noise map like seeded sampling does.
    small = [seed_noise_maps(pyramid, seed, size=(24, 40)) for seed in seeds]
    assert np.array_equal(sample_token_maps_from_noise(pyramid, small),
                          sample_token_maps(pyramid, seeds, size=(24, 40)))
    # Changing the noise changes the map; an empty request gives no maps.
    shifted = [[noise + 3.0 for noise in noises[0]]]
    assert not np.array_equal(sample_token_maps_from_noise(pyramid, shifted)[0],
                              sample_token_maps(pyramid, seeds[:1])[0])
    assert sample_token_maps_from_noise(pyramid, []).shape == (0, 32, 32)


def test_explicit_noise_maps_of_the_wrong_shape_are_named(pyramid):
    from sessgan_gen.sampling import sample_token_maps_from_noise, seed_noise_maps

    good = seed_noise_maps(pyramid, 1)
    with pytest.raises(ValueError, match='scales'):
        sample_token_maps_from_noise(pyramid, [good[:2]])
    with pytest.raises(ValueError, match='map 1'):
        sample_token_maps_from_noise(pyramid, [good, [good[0], good[1], good[2][:, :4]]])
    with pytest.raises(ValueError, match='scale 0'):
        sample_token_maps_from_noise(pyramid, [[g[:2] for g in good]])
