"""Tests of footprint inflation, regions, start/goal choice, paths and make_environment."""

import math

import numpy as np
import pytest

from sessgan_gen.environment import Environment, Pose2D
from sessgan_gen.navigation import (
    choose_start_goal,
    environment_is_feasible,
    footprint_free_mask,
    inflate,
    is_feasible,
    make_environment,
    most_open_cell,
    occupancy_passable_mask,
    passable_mask,
    plan_route,
    reachable_regions,
    shortest_path,
    shortest_path_in_free,
)
from sessgan_gen.token_map import parse_token_map

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


def test_corridor_start_and_goal_are_its_ends():
    cells = grid('WWWWWWWWWW\nWGGGGGGGGW\nWWWWWWWWWW\n')
    start, goal = choose_start_goal(cells, 'factory')
    assert {start, goal} == {(1, 1), (1, 8)}
    assert choose_start_goal(cells, 'factory') == (start, goal)  # deterministic


def test_start_and_goal_lie_in_the_largest_region():
    cells = grid("""WWWWWWWWWWWW
WGGWGGGGGGGW
WGGWGWWWWWWW
WWWWGGGGGGGW
WWWWWWWWWWWW""")
    # A U-shaped aisle (15 cells) beats the 2x2 room; its first cell is (1, 4), the
    # farthest from it is the top end (3, 10), and the farthest from that the bottom end.
    start, goal = choose_start_goal(cells, 'factory')
    assert (start, goal) == ((3, 10), (1, 10))
    path = shortest_path(cells, 'factory', start, goal)
    assert len(path) == 15 and path[0] == start and path[-1] == goal
    for (row_a, col_a), (row_b, col_b) in zip(path, path[1:], strict=False):
        assert abs(row_a - row_b) + abs(col_a - col_b) == 1


def test_goal_is_about_half_a_lap_on_a_loop():
    size = 20
    cells = np.ones((size, size), dtype=np.int64)
    cells[2:18, 2:18] = 0
    cells[6:14, 6:14] = 1   # a ring 4 cells wide, centre line 48 cells long
    start, goal = choose_start_goal(cells, 'racetrack')
    free_mask = footprint_free_mask(cells, 'racetrack')
    path = shortest_path_in_free(free_mask, start, goal)
    # The other way round the ring, avoiding the first path's interior.
    blocked_once = free_mask.copy()
    for cell in path[1:-1]:
        blocked_once[cell] = False
    other = shortest_path_in_free(blocked_once, start, goal)
    assert other, 'start and goal should be joined both ways round the loop'
    assert 0.6 < (len(path) - 1) / (len(other) - 1) <= 1.0


def test_feasibility_and_paths():
    cells = grid("""WWWWWWW
WGGWGGW
WGGWGGW
WWWWWWW""")
    assert is_feasible(cells, 'factory', (1, 1), (2, 2))
    assert not is_feasible(cells, 'factory', (1, 1), (1, 4))
    assert not is_feasible(cells, 'factory', (1, 1), (0, 0))  # goal on a wall
    assert shortest_path(cells, 'factory', (1, 1), (1, 4)) == []
    assert shortest_path(cells, 'factory', (1, 1), (1, 1)) == [(1, 1)]
    with pytest.raises(ValueError, match='outside'):
        is_feasible(cells, 'factory', (1, 1), (9, 9))


def test_no_diagonal_corner_cutting():
    mask = free("""
        .#
        #.
    """)
    assert shortest_path_in_free(mask, (0, 1), (1, 0)) == []


def test_make_environment_on_a_corridor():
    cells = grid('WWWWWWWW\nWGGGGGGW\nWGGGGGGW\nWWWWWWWW\n')
    environment = make_environment(cells, 'factory', 'env-1', seed=7, generation=3, member=2)
    assert isinstance(environment, Environment)
    environment.validate()
    assert environment.feasible
    assert (environment.id, environment.seed, environment.generation, environment.member) == (
        'env-1', 7, 3, 2)
    assert environment.resolution == 0.5 and environment.origin == (0.0, 0.0)
    assert environment.occupancy.dtype == np.int8
    assert environment.occupancy[0].tolist() == [100] * 8
    start_cell = environment.cell_of(environment.start.x, environment.start.y)
    goal_cell = environment.cell_of(environment.goal.x, environment.goal.y)
    assert {start_cell[1], goal_cell[1]} == {1, 6}
    # Poses sit at cell centres.
    assert environment.start.x == pytest.approx((start_cell[1] + 0.5) * 0.5)
    # Yaw points from start towards the goal along the corridor (x axis).
    direction = math.copysign(1.0, goal_cell[1] - start_cell[1])
    assert math.cos(environment.start.yaw) * direction > 0.7
    assert math.cos(environment.goal.yaw) * direction > 0.7
    assert environment.extra['path_length_m'] >= 5 * 0.5
    assert environment_is_feasible(environment)


def test_make_environment_without_room_for_the_robot():
    cells = np.ones((6, 6), dtype=np.int64)
    cells[2:4, 2:4] = 0   # 2x2 track: too narrow for the car
    environment = make_environment(cells, 'racetrack', 'tight')
    assert not environment.feasible
    assert environment.start == environment.goal
    assert environment.cell_of(environment.start.x, environment.start.y) == (2, 2)
    assert environment.extra['path_length_m'] == 0.0
    environment.validate()
    assert plan_route(cells, 'racetrack') is None
    assert choose_start_goal(cells, 'racetrack') is None
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
    occupancy = np.array([[0, 0, 100, 0]], dtype=np.int8)
    environment = Environment('e', 'factory', occupancy, 0.5, Pose2D(0.25, 0.25),
                              Pose2D(0.75, 0.25))
    assert environment_is_feasible(environment)
    environment.goal = Pose2D(1.75, 0.25)
    assert not environment_is_feasible(environment)
    environment.goal = Pose2D(9.0, 0.25)
    assert not environment_is_feasible(environment)


def test_a_short_route_is_not_feasible():
    from sessgan_gen.navigation import min_route_cells

    cells = np.ones((32, 32), dtype=np.int64)  # factory: all wall...
    cells[10, 10:14] = 0                        # ...but a 4-cell pocket
    environment = make_environment(cells, 'factory', 'pocket')
    assert environment.extra['path_length_m'] > 0  # a route exists
    assert not environment.feasible                 # but crosses too little of the map
    assert min_route_cells((32, 32)) == 16
