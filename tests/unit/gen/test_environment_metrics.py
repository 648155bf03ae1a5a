"""Tests of TPKL and uniqueness against hand computations and brute force."""

import math
from collections import Counter

import numpy as np
import pytest

from sessgan_gen.environment_metrics import (
    TPKL_EPSILON,
    tile_pattern_kl,
    tile_pattern_kl_per_k,
    uniqueness,
    uniqueness_report,
)

pytestmark = pytest.mark.unit

EPS = TPKL_EPSILON


def checkerboard(height, width):
    return np.indices((height, width)).sum(axis=0) % 2


def p(count, total):
    return (count + EPS) / ((total + EPS) * (1 + EPS))


def brute_tpkl(original, generated, k):
    def windows(grid):
        return [grid[r:r + k, c:c + k].tobytes() for r in range(grid.shape[0] - k + 1)
                for c in range(grid.shape[1] - k + 1)]
    counts_o = Counter(windows(original))
    counts_g = Counter(w for grid in generated for w in windows(grid))
    total_o, total_g = sum(counts_o.values()), sum(counts_g.values())
    return sum(p(c, total_o) * math.log(p(c, total_o) / p(counts_g[w], total_g))
               for w, c in counts_o.items())


def brute_uniqueness(generated, s):
    patches = [grid[r:r + s, c:c + s].tobytes() for grid in generated
               for r in range(grid.shape[0] - s + 1) for c in range(grid.shape[1] - s + 1)]
    return 100.0 * len(set(patches)) / len(patches)


def test_identical_maps_have_zero_divergence():
    rng = np.random.default_rng(0)
    original = rng.integers(0, 3, (12, 12))
    assert tile_pattern_kl(original, [original]) == 0.0
    per_k = tile_pattern_kl_per_k(original, [original, original.copy()])
    assert set(per_k) == {2, 3, 4}
    assert all(abs(value) < 1e-6 for value in per_k.values())


def test_checkerboard_against_all_ground_by_hand():
    original = checkerboard(3, 3)          # four 2x2 windows: two of each diagonal pattern
    generated = [np.zeros((3, 3), dtype=np.int64)]
    expected = 2 * p(2, 4) * math.log(p(2, 4) / p(0, 4))
    assert tile_pattern_kl_per_k(original, generated, ks=(2,))[2] == pytest.approx(expected)
    assert expected == pytest.approx(math.log(0.5 / (EPS / 4)), rel=1e-6)
    # The other direction: one pattern the generated maps never show.
    reverse = tile_pattern_kl_per_k(generated[0], [original], ks=(2,))[2]
    assert reverse == pytest.approx(p(4, 4) * math.log(p(4, 4) / p(0, 4)))


def test_partial_overlap_by_hand():
    original = np.array([[0, 0, 1]])     # 1x1 windows: 0 twice, 1 once
    generated = [np.array([[0, 1, 1, 1]])]  # 0 once, 1 three times
    expected = (p(2, 3) * math.log(p(2, 3) / p(1, 4))
                + p(1, 3) * math.log(p(1, 3) / p(3, 4)))
    assert tile_pattern_kl_per_k(original, generated, ks=(1,))[1] == pytest.approx(expected)


def test_tpkl_mean_over_k_and_matches_brute_force():
    rng = np.random.default_rng(1)
    original = (rng.random((14, 16)) < 0.3).astype(np.int64)
    generated = [(rng.random((14, 16)) < 0.3).astype(np.int64) for _ in range(3)]
    generated.append((rng.random((9, 11)) < 0.5).astype(np.int64))  # pooled, other size
    per_k = tile_pattern_kl_per_k(original, generated, ks=(2, 3, 4, 5))
    for k, value in per_k.items():
        assert value == pytest.approx(brute_tpkl(original, generated, k), rel=1e-9)
    assert tile_pattern_kl(original, generated, ks=(2, 3, 4, 5)) == pytest.approx(
        sum(per_k.values()) / 4)


def test_tpkl_with_a_large_alphabet_uses_exact_ranks():
    rng = np.random.default_rng(2)
    original = rng.integers(0, 200, (8, 8))
    generated = [rng.integers(0, 200, (8, 8)), original[:6, :7].copy()]
    for k, value in tile_pattern_kl_per_k(original, generated, ks=(2, 3, 4)).items():
        assert value == pytest.approx(brute_tpkl(original, generated, k), rel=1e-9)


def test_uniqueness_by_hand():
    constant = np.zeros((10, 10), dtype=np.int64)
    assert uniqueness([constant], sizes=(8,)) == {8: pytest.approx(100.0 / 9)}
    assert uniqueness([checkerboard(4, 4)], sizes=(2,)) == {2: pytest.approx(200.0 / 9)}
    # Pooling two equal maps halves the share of distinct patches; mixed sizes share codes.
    assert uniqueness([constant, constant], sizes=(8,))[8] == pytest.approx(100.0 / 18)
    mixed = [constant, np.zeros((12, 9), dtype=np.int64)]
    assert uniqueness(mixed, sizes=(8, 9))[8] == pytest.approx(100.0 / (9 + 10))
    assert uniqueness(mixed, sizes=(8, 9))[9] == pytest.approx(100.0 / (4 + 4))


@pytest.mark.parametrize('alphabet', [2, 3, 200])
def test_uniqueness_matches_brute_force(alphabet):
    rng = np.random.default_rng(alphabet)
    base = rng.integers(0, alphabet, (6, 6))
    generated = [np.kron(rng.integers(0, 2, (6, 6)), np.ones((3, 3), dtype=np.int64)) % alphabet,
                 np.tile(base, (3, 3)), rng.integers(0, alphabet, (17, 13))]
    sizes = (1, 2, 3, 5, 8, 9, 13, 16)
    result = uniqueness(generated, sizes=sizes)
    for size in sizes:
        expected = brute_uniqueness([g for g in generated if min(g.shape) >= size], size)
        assert result[size] == pytest.approx(expected), size


def test_uniqueness_report_mean():
    report = uniqueness_report([np.zeros((20, 20), dtype=np.int64)])
    assert report.per_size == {8: pytest.approx(100 / 169), 16: pytest.approx(100 / 25)}
    assert report.mean == pytest.approx((100 / 169 + 100 / 25) / 2)


def test_invalid_input_is_rejected():
    with pytest.raises(ValueError, match='no generated maps'):
        uniqueness([])
    with pytest.raises(ValueError, match='smaller than the 16x16 patch'):
        uniqueness([np.zeros((8, 8), dtype=np.int64)])
    with pytest.raises(ValueError, match='2-D'):
        tile_pattern_kl(np.zeros(4, dtype=np.int64), [np.zeros((4, 4), dtype=np.int64)])
    with pytest.raises(ValueError, match='integers'):
        tile_pattern_kl(np.zeros((4, 4)), [np.zeros((4, 4), dtype=np.int64)])
    with pytest.raises(ValueError, match='negative'):
        uniqueness([np.full((9, 9), -1)], sizes=(8,))
    with pytest.raises(ValueError, match='smaller than the 4x4 tile'):
        tile_pattern_kl(np.zeros((3, 3), dtype=np.int64), [np.zeros((5, 5), dtype=np.int64)])


def test_uniqueness_of_fitting_sizes_skips_patches_larger_than_every_map():
    from sessgan_gen.environment_metrics import uniqueness_of_fitting_sizes

    small = [np.eye(12, 16, dtype=np.int64), np.zeros((10, 9), dtype=np.int64)]
    assert list(uniqueness_of_fitting_sizes(small)) == [8]
    assert uniqueness_of_fitting_sizes(small)[8] == pytest.approx(uniqueness(small, [8])[8])
    assert uniqueness_of_fitting_sizes([np.zeros((6, 6), dtype=np.int64)]) == {}
    with pytest.raises(ValueError, match='smaller than the 16x16'):
        uniqueness(small)
