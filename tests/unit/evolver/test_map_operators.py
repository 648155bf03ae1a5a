"""Operators of the grid GA (token maps) and of latent search (noise maps)."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_evolver.map_operators import (
    MapOperatorError,
    crossover_noise,
    crossover_token_maps,
    mutate_noise,
    mutate_noise_region,
    mutate_token_map,
)

pytestmark = pytest.mark.unit


def test_token_map_mutation_is_seeded_local_and_keeps_the_border():
    cells = np.zeros((16, 16), dtype=np.int64)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 1
    seen = set()
    for seed in range(40):
        child, operation = mutate_token_map(cells, 2, np.random.default_rng(seed), border=1)
        again, _ = mutate_token_map(cells, 2, np.random.default_rng(seed), border=1)
        assert np.array_equal(child, again) and child is not cells
        assert np.all(child[0] == 1) and np.all(child[:, -1] == 1)
        assert np.count_nonzero(child != cells) <= 36  # one rectangle of at most 6 x 6
        seen.add(operation)
    assert seen == {'paint', 'scatter', 'move'}
    assert np.all(cells[1:-1, 1:-1] == 0)  # the parent is untouched
    with pytest.raises(MapOperatorError):
        mutate_token_map(cells, 1, np.random.default_rng(0))


def test_token_map_crossover_takes_a_rectangle_of_the_second_parent():
    first, second = np.zeros((12, 12), dtype=np.int64), np.ones((12, 12), dtype=np.int64)
    child = crossover_token_maps(first, second, np.random.default_rng(3))
    taken = np.argwhere(child == 1)
    rows, cols = taken[:, 0], taken[:, 1]
    assert len(taken) == (np.ptp(rows) + 1) * (np.ptp(cols) + 1)  # one full rectangle
    assert 3 <= np.ptp(rows) + 1 <= 9 and 3 <= np.ptp(cols) + 1 <= 9
    with pytest.raises(MapOperatorError, match='shape'):
        crossover_token_maps(first, np.ones((12, 11)), np.random.default_rng(0))


def test_noise_mutation_keeps_shapes_and_standard_normal_statistics():
    rng = np.random.default_rng(0)
    noise = [rng.standard_normal((2, 8, 8)).astype(np.float32),
             rng.standard_normal((2, 64, 64)).astype(np.float32)]
    child = mutate_noise(noise, np.random.default_rng(1), strength=0.6, scale_probability=1.0)
    assert [c.shape for c in child] == [n.shape for n in noise]
    assert abs(float(child[1].std()) - 1.0) < 0.05 and abs(float(child[1].mean())) < 0.05
    correlation = np.corrcoef(child[1].ravel(), noise[1].ravel())[0, 1]
    assert correlation == pytest.approx(0.8, abs=0.03)  # sqrt(1 - 0.6^2)
    assert all(np.array_equal(a, b) for a, b in
               zip(mutate_noise(noise, np.random.default_rng(1), 0.0), noise))
    with pytest.raises(MapOperatorError):
        mutate_noise(noise, rng, 1.5)
    # Named scales: exactly those change, whatever the draw.
    for seed in range(5):
        fine = mutate_noise(noise, np.random.default_rng(seed), 0.3, scales=(1,))
        assert np.array_equal(fine[0], noise[0]) and not np.array_equal(fine[1], noise[1])
    with pytest.raises(MapOperatorError, match='scales'):
        mutate_noise(noise, rng, 0.3, scales=(2,))


def test_regional_noise_mutation_changes_only_its_rectangle_on_its_scales():
    rng = np.random.default_rng(0)
    noise = [rng.standard_normal((2, 8, 8)).astype(np.float32),
             rng.standard_normal((2, 32, 32)).astype(np.float32)]
    child = mutate_noise_region(noise, np.random.default_rng(1), 1.0, (0.25, 0.5, 0.5, 0.75),
                                scales=(1,))
    assert np.array_equal(child[0], noise[0])
    changed = np.any(child[1] != noise[1], axis=0)
    rows, cols = np.nonzero(changed)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (8, 15, 16, 23)
    assert changed.sum() == 8 * 8
    # A region smaller than a coarse noise cell still changes one cell there.
    coarse = mutate_noise_region(noise, np.random.default_rng(1), 1.0,
                                 (0.5, 0.5, 0.51, 0.51), scales=(0,))
    assert np.any(coarse[0] != noise[0], axis=0).sum() == 1
    with pytest.raises(MapOperatorError, match='region'):
        mutate_noise_region(noise, rng, 0.5, (0.5, 0.0, 0.5, 1.0), scales=(1,))


def test_noise_crossover_takes_whole_scales():
    first = [np.zeros((1, 2, 2), np.float32) for _ in range(6)]
    second = [np.ones((1, 2, 2), np.float32) for _ in range(6)]
    child = crossover_noise(first, second, np.random.default_rng(4))
    assert all(np.all(scale == scale.flat[0]) for scale in child)
    assert {float(scale.flat[0]) for scale in child} == {0.0, 1.0}
