"""The Environment's own checks: safe ids and bounded grids, refused before any work."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_core.environment import (
    MAX_TOTAL_CELLS,
    Environment,
    Pose2D,
    check_grid_size,
)
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_gen.environment_sampler import EnvironmentSampler, SamplingRequestError

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def environment(height: int, width: int, environment_id: str = 'env-1') -> Environment:
    return Environment(id=environment_id, scenario='factory',
                       occupancy=np.zeros((height, width), dtype=np.int8), resolution=0.5,
                       start=Pose2D(0.25, 0.25), goal=Pose2D(0.75, 0.25))


def test_the_total_cells_of_a_grid_are_bounded():
    assert MAX_TOTAL_CELLS == 1024 * 1024
    environment(1024, 1024).validate()
    environment(1, 4096).validate()
    for height, width in ((1025, 1024), (2048, 2048), (4096, 4096)):
        with pytest.raises(InvalidEnvironmentError, match=f'{width}x{height} has .* cells, '
                                                          'more than the 1,048,576'):
            environment(height, width).validate()
    with pytest.raises(InvalidEnvironmentError, match='per side'):
        check_grid_size(4097, 1)
    with pytest.raises(InvalidEnvironmentError, match='per side'):
        check_grid_size(0, 5)


def test_validate_refuses_an_unsafe_id():
    for unsafe in ('../victim', '/tmp/x', ''):
        with pytest.raises(InvalidEnvironmentError, match='environment id'):
            environment(4, 4, unsafe).validate()


def test_the_sampler_refuses_oversized_requests_before_sampling():
    sampler = EnvironmentSampler(max_cells_per_request=3 * 32 * 32)
    assert len(sampler.sample([1, 2, 3], scenario='factory')) == 3
    with pytest.raises(SamplingRequestError, match='4 maps of 32x32 are 4,096 cells, more than '
                                                   '3,072 per request'):
        sampler.sample([1, 2, 3, 4], scenario='factory')
    with pytest.raises(SamplingRequestError, match='more than the 1,048,576'):
        EnvironmentSampler().sample([1], scenario='factory', size=(1100, 1000))
    with pytest.raises(SamplingRequestError, match='max_cells_per_request must be >= 1'):
        EnvironmentSampler(max_cells_per_request=0)
