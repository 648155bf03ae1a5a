"""Tests of the track-realism measures on hand-made tracks."""

import math

import numpy as np
import pytest

from sessgan_core.scenarios import get_scenario
from sessgan_core.valid_tests import make_environment
from sessgan_gen.track_realism import (
    count_dead_ends,
    measure_environment,
    measure_track,
    paint_discs,
    route_curvatures,
    skeleton,
    skeleton_end_points,
    track_clearance,
)

pytestmark = pytest.mark.unit


def straight(width=5, length=40, shape=(20, 60), row0=5, col0=8):
    track = np.zeros(shape, dtype=bool)
    track[row0:row0 + width, col0:col0 + length] = True
    return track


def ring(size=60, centre=29.5, inner=12.0, outer=17.0):
    """A round closed track 5 cells wide (centre line at radius 14.5)."""
    rows, cols = np.mgrid[0:size, 0:size]
    radius = np.hypot(rows + 0.5 - (centre + 0.5), cols + 0.5 - (centre + 0.5))
    return (radius >= inner) & (radius < outer)


def arc(radius, start, stop, centre=(30.0, 30.0), count=60):
    """Points (x, y) in cells on a circle, from angle ``start`` to ``stop``."""
    angles = np.linspace(start, stop, count)
    return np.column_stack([centre[0] + radius * np.cos(angles),
                            centre[1] + radius * np.sin(angles)])


def test_clearance_is_the_distance_to_the_nearest_non_track_square():
    track = straight()
    clearance = track_clearance(track)
    assert clearance[7, 20] == pytest.approx(2.5)     # centre line of a 5-wide straight
    assert clearance[5, 20] == pytest.approx(0.5)     # edge row
    assert clearance[0, 0] == 0.0                     # off the track
    # The outside of the grid is not track.
    assert track_clearance(np.ones((3, 3), dtype=bool))[1, 1] == pytest.approx(1.5)
    # Diagonal: a blocked square touching only at a corner.
    lone = np.ones((5, 5), dtype=bool)
    lone[0, 0] = False
    assert track_clearance(lone)[1, 1] == pytest.approx(math.sqrt(0.5))


def test_a_straight_of_width_5_measures_5_wherever_the_route_runs_on_it():
    track = straight()
    centre = np.array([[12.0, 7.5], [44.0, 7.5]])
    hugging = np.array([[12.0, 5.9], [44.0, 5.9]])    # 0.9 cells from the lower edge
    for route in (centre, hugging):
        result = measure_track(track, route)
        assert np.allclose(result.route_widths, 5.0)
        assert result.route_curvatures.max() < 1e-9
        assert result.dead_ends == 2
        assert result.fragments == 1 and result.route_component_fraction == 1.0
        assert not result.closed_lap
        assert result.lap_corridor_fraction == result.route_corridor_fraction
        assert 0.75 < result.route_corridor_fraction < 1.0
    # Metres: two metres a cell.
    assert np.allclose(measure_track(track, centre, cell_size=2.0).route_widths, 10.0)


def test_a_closed_ring_has_no_dead_end_and_its_lap_covers_it():
    track = ring()
    result = measure_track(track, arc(14.5, 0.0, math.pi), route_clearance=0.9)
    assert result.dead_ends == 0 and result.fragments == 1
    # The route is half the ring; the way back is the other half.
    assert 0.4 < result.route_corridor_fraction < 0.7
    assert result.closed_lap and result.lap_corridor_fraction > 0.97
    # A digitised round ring is 5 cells wide across rows and columns, 4.24 on diagonals.
    assert 4.2 <= result.route_widths.min() and result.route_widths.max() <= 6.0
    # Curvature of the smoothed route: about 1 / 14.5 rad per cell.
    assert np.median(result.route_curvatures) == pytest.approx(1 / 14.5, rel=0.15)


def test_a_t_junction_on_the_ring_is_one_dead_end_that_the_lap_leaves_out():
    track = ring()
    track[27:32, 46:60] = True          # a 5-wide stub out of the ring's right side, 13 long
    assert count_dead_ends(track) == 1
    result = measure_track(track, arc(14.5, 0.5 * math.pi, 1.5 * math.pi),
                           route_clearance=0.9)
    assert result.dead_ends == 1 and result.closed_lap
    stub_share = track[27:32, 48:60].sum() / track.sum()
    assert result.lap_corridor_fraction < 1.0 - 0.8 * stub_share
    assert result.lap_corridor_fraction > 0.9 - stub_share


def test_a_t_of_straights_has_three_dead_ends_and_short_bumps_none():
    track = np.zeros((50, 50), dtype=bool)
    track[30:35, 5:45] = True           # the bar
    track[5:30, 22:27] = True           # the stem
    assert count_dead_ends(track) == 3
    bumpy = ring()
    bumpy[28:31, 46:49] = True          # a bump shorter than the track is wide
    assert count_dead_ends(bumpy) == 0
    # Thinning keeps the ring closed.
    thin = skeleton(ring())
    assert thin.sum() > 2 * math.pi * 12


def test_fragments_and_maps_without_a_route():
    track = straight(shape=(40, 60))
    track[25:30, 8:48] = True           # a second, parallel straight
    result = measure_track(track, np.array([[12.0, 7.5], [44.0, 7.5]]))
    assert result.fragments == 2 and result.dead_ends == 4
    assert result.route_component_fraction == pytest.approx(0.5)
    assert result.route_corridor_fraction < 0.5    # never across the barrier
    none = measure_track(track, None)
    assert (none.route_corridor_fraction, none.lap_corridor_fraction, none.closed_lap) == (
        0.0, 0.0, False)
    assert none.route_widths.size == 0 and none.route_curvatures.size == 0
    assert none.fragments == 2 and none.dead_ends == 4


def test_route_curvature_of_straights_corners_and_circles():
    assert np.allclose(route_curvatures(np.array([[0.0, 0.0], [20.0, 0.0]])), 0.0)
    circle = arc(10.0, 0.0, 1.5 * math.pi, count=200)
    assert np.median(route_curvatures(circle)) == pytest.approx(0.1, rel=0.05)
    # A right-angle corner turns pi/2 in all, spread over the smoothing window.
    corner = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]])
    turns = route_curvatures(corner, step_m=0.5, smoothing_m=4.0)
    turning = turns > 1e-6
    assert 4 <= turning.sum() <= 10           # about the 8 samples of the 4 m window
    assert turns.max() < 1.0                  # a kink would be (pi / 2) / 0.5 m = 3.1
    assert route_curvatures(np.array([[0.0, 0.0], [1.0, 0.0]])).size == 0


def test_measure_environment_of_a_generated_style_race_track_ring():
    spec = get_scenario('racetrack')
    cells = np.full((128, 128), spec.token_id('O'), dtype=np.int64)
    rows, cols = np.mgrid[0:128, 0:128]
    radius = np.hypot(rows - 63.5, cols - 63.5)
    cells[(radius >= 40) & (radius < 46)] = spec.token_id('T')
    environment = make_environment(cells, spec, 'ring', seed=3)
    assert environment.feasible
    result = measure_environment(environment)
    assert result.dead_ends == 0 and result.fragments == 1
    assert result.closed_lap and result.lap_corridor_fraction > 0.9
    assert 0.3 < result.route_corridor_fraction < 0.7
    assert 5.0 <= np.median(result.route_widths) <= 7.0
    # The taut route is a polygon of chords: its mean turn per metre is the ring's.
    assert np.mean(result.route_curvatures) == pytest.approx(1 / 43, rel=0.3)
    # An infeasible map: no route measures, the rest still measured.
    cells[:] = spec.token_id('O')
    cells[10:12, 10:20] = spec.token_id('T')
    blocked = make_environment(cells, spec, 'stub', seed=3)
    assert not blocked.feasible
    result = measure_environment(blocked)
    assert result.route_widths.size == 0 and result.fragments == 1


def test_painted_discs_cover_the_cells_within_any_radius():
    rng = np.random.default_rng(5)
    height, width = 23, 31
    rows, cols = rng.integers(0, height, 12), rng.integers(0, width, 12)
    radii = rng.choice([0.0, 1.0, math.sqrt(2), 2.5, math.sqrt(13), 4.0], 12)
    grid_rows, grid_cols = np.mgrid[:height, :width]
    expected = np.zeros((height, width), dtype=bool)
    for row, col, radius in zip(rows, cols, np.round(radii, 6)):  # sqrt(13) rounds down
        expected |= (grid_rows - row) ** 2 + (grid_cols - col) ** 2 <= radius * radius + 1e-9
    assert np.array_equal(paint_discs((height, width), rows, cols, radii), expected)
    assert not paint_discs((4, 4), rows[:0], cols[:0], radii[:0]).any()


def random_masks(seed, count=40):
    """Random masks from speckle to wide blobs (wider than track_clearance's first band)."""
    rng = np.random.default_rng(seed)
    masks = []
    for index in range(count):
        field = rng.random((int(rng.integers(3, 50)), int(rng.integers(3, 50))))
        for _ in range(index % 6):
            field = (field + np.roll(field, 1, 0) + np.roll(field, 1, 1)) / 3
        masks.append(field < np.quantile(field, rng.uniform(0.3, 1.0)))
    masks.append(np.ones((40, 45), dtype=bool))  # clearance up to 20 cells
    return masks


def brute_force_clearance(track):
    """Each track cell's distance to every non-track square (the outside included)."""
    height, width = track.shape
    blocked = np.pad(~track, 1, constant_values=True)
    b_rows, b_cols = np.nonzero(blocked)
    out = np.zeros(track.shape)
    for row, col in zip(*np.nonzero(track)):
        d_row = np.maximum(np.abs(b_rows - (row + 1)) - 0.5, 0.0)
        d_col = np.maximum(np.abs(b_cols - (col + 1)) - 0.5, 0.0)
        out[row, col] = np.sqrt(d_row ** 2 + d_col ** 2).min()
    return out


def zhang_suen_reference(track):
    """Zhang-Suen thinning written out condition by condition (the lookup tables' source)."""
    image = np.pad(track.astype(np.uint8), 1)
    order = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
    while True:
        changed = False
        for sub_iteration in (0, 1):
            remove = []
            for row, col in zip(*np.nonzero(image)):
                p = [image[row + d_row, col + d_col] for d_row, d_col in order]
                transitions = sum(p[k] == 0 and p[(k + 1) % 8] == 1 for k in range(8))
                p2, _, p4, _, p6, _, p8, _ = p
                side = ((p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0) if sub_iteration == 0
                        else (p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0))
                if 2 <= sum(p) <= 6 and transitions == 1 and side:
                    remove.append((row, col))
            for row, col in remove:
                image[row, col] = 0
            changed |= bool(remove)
        if not changed:
            return image[1:-1, 1:-1].astype(bool)


def test_clearance_skeleton_and_end_points_match_their_definitions_on_random_masks():
    for mask in random_masks(11):
        assert np.allclose(track_clearance(mask), brute_force_clearance(mask), atol=1e-12)
        thin = skeleton(mask)
        assert np.array_equal(thin, zhang_suen_reference(mask))
        ends = skeleton_end_points(thin)
        padded = np.pad(thin, 1)
        for row, col in zip(*np.nonzero(thin)):
            around = [padded[row + 1 + d_row, col + 1 + d_col]
                      for d_row, d_col in ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1),
                                           (0, -1), (-1, -1))]
            runs = sum(not around[k] and around[(k + 1) % 8] for k in range(8))
            assert ends[row, col] == (sum(around) <= 2 and runs <= 1)
