"""Tests of footprint inflation, regions, paths and make_environment (placement and the route
certificate themselves: test_route_certificate.py)."""


import numpy as np
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.token_map import parse_token_map
from sessgan_core.valid_tests import (
    environment_is_feasible,
    footprint_free_mask,
    inflate,
    make_environment,
    most_open_cell,
    occupancy_passable_mask,
    passable_mask,
    reachable_regions,
    shortest_path_in_free,
    shortest_paths_from,
)

pytestmark = pytest.mark.unit


def grid(text, scenario='factory'):
    """Token cells from rows written top first, like a file."""
    return parse_token_map(text, scenario).cells


def free(text):
    """Bool mask from rows of '.' (free) and '#' (blocked), top row first."""
    rows = [line.strip() for line in text.strip().splitlines()]
    return np.array([[char == '.' for char in row] for row in rows[::-1]])


def test_passable_mask_uses_traversable_tokens():
    cells = np.array([[0, 1, 2]])
    assert passable_mask(cells, 'drone').tolist() == [[True, False, True]]
    assert passable_mask(cells[:, :2], 'factory').tolist() == [[True, False]]
    occupancy = np.array([[0, 100, 50, -1]])
    assert occupancy_passable_mask(occupancy, 'drone').tolist() == [[True, False, True, False]]
    assert occupancy_passable_mask(occupancy, 'factory').tolist() == [[True, False, False,
                                                                        False]]


def test_inflate_measures_to_the_nearest_point_of_blocked_squares():
    mask = np.ones((7, 7), dtype=bool)
    mask[3, 3] = False
    # Radius below half a cell: nothing but the blocked cell itself.
    assert (inflate(mask, 0.4) == mask).all() and inflate(mask, 0.0).sum() == 48
    # 0.6 cells: the four edge neighbours (0.5 away) are out, diagonals (0.707) stay.
    out = inflate(mask, 0.6)
    assert not out[2:5, 3].any() and not out[3, 2:5].any()
    assert out[2, 2] and out[4, 4]
    # 0.75 cells: diagonals too; the next ring (1.5 away) stays.
    out = inflate(mask, 0.75)
    assert not out[2:5, 2:5].any() and out[1:6, 1:6].sum() == 16
    # The outside of the grid is blocked.
    assert not inflate(np.ones((3, 3), dtype=bool), 0.6)[0].any()
    assert inflate(np.ones((3, 3), dtype=bool), 0.6)[1, 1]
    assert inflate(mask, 0.6).dtype == bool
    with pytest.raises(ValueError, match='radius'):
        inflate(mask, -1.0)


def test_footprints_of_the_scenarios():
    # A one-cell gap: the 0.4 m ground robot fits (0.5 m cells), even at the grid's edge.
    factory = grid('WWWWW\nGGGGG\nWWWWW\n')
    assert footprint_free_mask(factory, 'factory')[1].all()
    track = grid('OOOOOO\nTTTTTT\nTTTTTT\nTTTTTT\nOOOOOO\n', 'racetrack')
    car = footprint_free_mask(track, 'racetrack')
    assert car.sum() == 4 and car[2, 1:5].all()
    # The drone flies over low obstacles.
    drone = grid('WWWWW\nGOOOG\nWWWWW\n', 'drone')
    assert footprint_free_mask(drone, 'drone')[1, 1:4].all()


def test_reachable_regions_are_four_connected():
    mask = free("""
        ..#.
        ..#.
        ##.#
        ...#
    """)
    regions = reachable_regions(mask)
    # Diagonal contact does not connect regions; regions numbered in row-major order.
    assert regions.sizes == [4, 4, 2]
    assert regions.labels[0].tolist() == [0, 0, 0, -1]
    assert regions.labels[1].tolist() == [-1, -1, 0, -1]
    assert regions.labels[2].tolist() == [1, 1, -1, 2]
    assert regions.labels.dtype == np.int32


def flood_fill_labels(mask):
    """Reference labelling: a flood fill from each unlabelled cell in row-major order."""
    labels = np.full(mask.shape, -1)
    sizes = []
    for seed in zip(*np.nonzero(mask)):
        if labels[seed] >= 0:
            continue
        labels[seed] = len(sizes)
        stack, size = [seed], 0
        while stack:
            row, col = stack.pop()
            size += 1
            for n_row, n_col in ((row - 1, col), (row + 1, col), (row, col - 1), (row, col + 1)):
                if (0 <= n_row < mask.shape[0] and 0 <= n_col < mask.shape[1]
                        and mask[n_row, n_col] and labels[n_row, n_col] < 0):
                    labels[n_row, n_col] = len(sizes)
                    stack.append((n_row, n_col))
        sizes.append(size)
    return labels, sizes


def spiral(side):
    """A one-cell corridor wound inwards: each turn joins runs only through the next row."""
    mask = np.zeros((side, side), dtype=bool)
    top, left, bottom, right = 0, 0, side - 1, side - 1
    while top <= bottom and left <= right:
        mask[top, left:right + 1] = True
        mask[top:bottom + 1, right] = True
        mask[bottom, left:right + 1] = True
        mask[top + 2:bottom + 1, left] = True
        top, left, bottom, right = top + 2, left + 2, bottom - 2, right - 2
        if top <= bottom:
            mask[top - 1, left] = True
    return mask


def test_region_labels_match_a_flood_fill():
    rng = np.random.default_rng(7)
    masks = [spiral(21), spiral(8), np.zeros((3, 4), bool), np.ones((5, 1), bool)]
    masks += [rng.random(rng.integers(1, 30, 2)) < rng.random() for _ in range(200)]
    for mask in masks:
        regions = reachable_regions(mask)
        labels, sizes = flood_fill_labels(mask)
        assert regions.labels.tolist() == labels.tolist()
        assert regions.sizes == sizes


def test_shortest_path_in_free():
    mask = free("""
        ..#..
        ..#..
    """)
    assert shortest_path_in_free(mask, (0, 0), (1, 1)) in ([(0, 0), (0, 1), (1, 1)],
                                                           [(0, 0), (1, 0), (1, 1)])
    assert shortest_path_in_free(mask, (0, 0), (0, 4)) == []
    assert shortest_path_in_free(mask, (0, 0), (0, 2)) == []  # goal on a wall
    assert shortest_path_in_free(mask, (1, 1), (1, 1)) == [(1, 1)]
    with pytest.raises(ValueError, match='outside'):
        shortest_path_in_free(mask, (0, 0), (9, 9))


def test_no_diagonal_corner_cutting():
    mask = free("""
        .#
        #.
    """)
    assert shortest_path_in_free(mask, (0, 1), (1, 0)) == []


def test_make_environment_in_a_hall():
    cells = np.zeros((32, 32), dtype=np.int64)
    cells[[0, -1], :] = 1
    cells[:, [0, -1]] = 1
    cells[10:22, 15:17] = 1  # a wall in the middle of the hall
    environment = make_environment(cells, 'factory', 'env-1', seed=7, generation=3, member=2)
    assert isinstance(environment, Environment)
    environment.validate()
    assert environment.feasible and environment.extra['rejection'] == ''
    assert (environment.id, environment.seed, environment.generation, environment.member) == (
        'env-1', 7, 3, 2)
    assert environment.resolution == 0.5 and environment.origin == (0.0, 0.0)
    assert environment.occupancy.dtype == np.int8
    assert environment.occupancy[0].tolist() == [100] * 32
    # Far apart: at least half the map's side along the route.
    assert environment.route_length >= 0.5 * 32 * 0.5 * 0.7
    assert environment.route_min_clearance >= 0.2 + 0.1
    assert environment.extra['start_clearance'] >= 0.45
    assert environment_is_feasible(environment)
    same = make_environment(cells, 'factory', 'env-1', seed=7)
    assert (same.start, same.goal) == (environment.start, environment.goal)
    other = make_environment(cells, 'factory', 'env-1', seed=8)
    assert (other.start, other.goal) != (environment.start, environment.goal)


def test_make_environment_without_room_for_the_robot():
    cells = np.ones((6, 6), dtype=np.int64)
    cells[2:4, 2:4] = 0   # 2x2 track: too narrow for the car
    environment = make_environment(cells, 'racetrack', 'tight')
    assert not environment.feasible
    assert environment.extra['rejection'] == 'no_clear_cell'
    assert environment.start == environment.goal
    assert environment.cell_of(environment.start.x, environment.start.y) == (2, 2)
    assert environment.route_length == 0.0
    environment.validate()
    all_walls = make_environment(np.ones((4, 4), dtype=np.int64), 'factory', 'walls')
    assert not all_walls.feasible
    all_walls.validate()


def test_most_open_cell_prefers_room():
    cells = grid("""WWWWWWWWW
WGWGGGGGW
WWWGGGGGW
WGWGGGGGW
WWWWWWWWW""")
    assert most_open_cell(cells, 'factory') == (2, 5)


def test_environment_is_feasible_checks_the_poses():
    occupancy = np.zeros((4, 12), dtype=np.int8)
    occupancy[:, 6] = 100
    environment = Environment('e', 'factory', occupancy, 0.5, Pose2D(0.5, 1.0),
                              Pose2D(2.5, 1.0))
    assert environment_is_feasible(environment)
    environment.goal = Pose2D(4.5, 1.0)  # behind the wall
    assert not environment_is_feasible(environment)
    environment.goal = Pose2D(9.0, 1.0)  # outside the grid
    assert not environment_is_feasible(environment)
    environment.goal = Pose2D(2.9, 1.0)  # 0.1 m from the wall: no clearance for the route
    assert not environment_is_feasible(environment)


def test_a_short_route_is_not_a_valid_test():
    cells = np.ones((32, 32), dtype=np.int64)  # factory: all wall...
    cells[10:14, 10:16] = 0                     # ...but a small room
    environment = make_environment(cells, 'factory', 'pocket')
    assert not environment.feasible
    assert environment.extra['rejection'] == 'no_far_goal'


def test_descend_follows_a_distance_field_to_its_origin():
    from sessgan_core.grid_search import descend, distance_field

    mask = free("""
        .....
        .###.
        .....
    """)
    field = distance_field(mask, (0, 0))
    path = descend(field, (2, 4))
    assert path[0] == (2, 4) and path[-1] == (0, 0) and len(path) == 7
    assert descend(field, (1, 2)) == []  # a wall
    assert descend(field, (5, 5)) == []  # outside


def _eight_connected_steps(mask, source):
    """Oracle: breadth-first search, one cell at a time, over the 8 neighbours."""
    from collections import deque

    steps = np.full(mask.shape, np.inf)
    if not mask[source]:
        return steps
    steps[source] = 0.0
    queue = deque([source])
    while queue:
        row, col = queue.popleft()
        for d_row in (-1, 0, 1):
            for d_col in (-1, 0, 1):
                n_row, n_col = row + d_row, col + d_col
                if (0 <= n_row < mask.shape[0] and 0 <= n_col < mask.shape[1]
                        and mask[n_row, n_col] and np.isinf(steps[n_row, n_col])):
                    steps[n_row, n_col] = steps[row, col] + 1.0
                    queue.append((n_row, n_col))
    return steps


@pytest.mark.parametrize('seed', range(6))
def test_the_diagonal_distance_field_is_breadth_first_search(seed):
    from sessgan_core.grid_search import distance_field

    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(1, 30)), int(rng.integers(1, 30)))
    mask = rng.random(shape) < 0.7
    for source in [(0, 0), (shape[0] - 1, shape[1] - 1),
                   (int(rng.integers(shape[0])), int(rng.integers(shape[1])))]:
        field = distance_field(mask, source, diagonal=True)
        np.testing.assert_array_equal(field, _eight_connected_steps(mask, source))
    # Past two blocked corners: one step.
    checker = np.array([[True, False], [False, True]])
    assert distance_field(checker, (0, 0), diagonal=True)[1, 1] == 1.0
    assert np.isinf(distance_field(mask, (-1, 0), diagonal=True)).all()


@pytest.mark.parametrize('seed', range(6))
def test_searches_that_stop_at_their_goal_find_the_paths_of_full_searches(seed):
    from sessgan_core.grid_search import bfs, flat_grid, to_cell, to_flat, walk_back

    rng = np.random.default_rng(seed)
    mask = rng.random((int(rng.integers(2, 40)), int(rng.integers(2, 40)))) < 0.75
    flat = flat_grid(mask)
    free = list(zip(*np.nonzero(mask)))
    starts = [free[int(i)] for i in rng.integers(len(free), size=4)]
    for start in starts:
        full = [-1] * len(flat.open_cells)
        bfs(flat, to_flat(flat, start), full)
        # One search answering every goal in a random order (the agents' patrols ask some).
        lazy = shortest_paths_from(mask, start, flat)
        for asked, goal in enumerate(free[int(i)] for i in rng.permutation(len(free))):
            target = to_flat(flat, goal)
            expected = walk_back(flat, full, target) if full[target] >= 0 else []
            assert lazy(goal) == [to_cell(flat, index) for index in expected]
            if asked >= 10:
                continue
            stopped = [-1] * len(flat.open_cells)
            bfs(flat, to_flat(flat, start), stopped, target)
            assert (walk_back(flat, stopped, target) if stopped[target] >= 0 else []) == expected
            if 0 <= full[target] < max(full):  # it stopped before the farthest cells
                assert sum(d >= 0 for d in stopped) < sum(d >= 0 for d in full)
