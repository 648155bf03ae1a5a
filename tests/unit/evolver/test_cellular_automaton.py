"""The BARN-style cellular automaton: seeded, the scenario's tokens, the example's border."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_evolver.cellular_automaton import (
    CellularAutomatonConfig,
    CellularAutomatonError,
    CellularAutomatonGenerator,
    smooth,
)

pytestmark = pytest.mark.unit


def test_smoothing_follows_birth_and_survival():
    grid = np.zeros((5, 5), dtype=bool)
    grid[1:4, 1:4] = True
    grid[2, 2] = False  # a free cell with 8 obstacle neighbours is born
    lone = np.zeros((5, 5), dtype=bool)
    lone[2, 2] = True
    assert smooth(grid, 1, birth=5, survival=4)[2, 2]
    assert not smooth(lone, 1, birth=5, survival=4)[2, 2]  # 0 neighbours: it dies
    assert smooth(lone, 0, 5, 4)[2, 2]
    # Beyond the grid counts as obstacle: a corner cell has 5 outside neighbours.
    assert smooth(np.zeros((4, 4), dtype=bool), 1, 5, 4)[0, 0]


@pytest.mark.parametrize('scenario,tokens', [('factory', {0, 1}), ('drone', {0, 1, 2})])
def test_maps_are_seeded_and_use_the_scenarios_tokens(scenario, tokens):
    generator = CellularAutomatonGenerator(scenario)
    maps = generator.maps([1, 2, 3, 4])
    assert maps.shape == (4, 32, 32) and maps.dtype == np.int64
    assert np.array_equal(generator.one(3), maps[2])
    assert not np.array_equal(maps[0], maps[1])
    assert set(np.unique(maps)) == tokens
    border = np.concatenate([maps[:, 0], maps[:, -1], maps[:, :, 0], maps[:, :, -1]])
    assert generator.border == 1 and np.all(border == 1)  # the example maps' wall ring
    assert generator.maps([]).shape == (0, 32, 32)


def test_bad_settings_are_named():
    with pytest.raises(CellularAutomatonError, match='fill_range'):
        CellularAutomatonGenerator('factory', CellularAutomatonConfig(fill_range=(0.5, 0.2)))
    with pytest.raises(CellularAutomatonError, match='birth'):
        CellularAutomatonGenerator('factory', CellularAutomatonConfig(birth=9))
