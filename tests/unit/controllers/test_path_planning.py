"""Global planning: A* (optimality, no corner cutting), clearance-keeping smoothing, paths."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import MapData
from sessgan_controllers.costmap import Costmap, CostmapConfig
from sessgan_controllers.path_planning import (
    Path,
    PlannerConfig,
    PlanningError,
    astar,
    plan_path,
)

pytestmark = pytest.mark.unit

COSTMAP = CostmapConfig(robot_radius=0.2, safety_margin=0.05, inflation_radius=0.5,
                        cost_scaling_factor=6.0, cost_weight=3.0, inscribed_penalty=50.0,
                        resolution=0.1)
PLANNER = PlannerConfig(spacing=0.05, wanted_clearance=0.5, smoothing_allowance=0.15,
                        inscribed=0.25)


def grid_map(rows: list[str], resolution: float = 0.5) -> MapData:
    occupancy = np.array([[100 if char == '#' else 0 for char in row] for row in reversed(rows)],
                         dtype=np.int8)
    return MapData(occupancy, resolution)


def path_cost(penalty: np.ndarray, cells: list[tuple[int, int]]) -> float:
    total = 0.0
    for (r0, c0), (r1, c1) in zip(cells, cells[1:]):
        total += math.hypot(r1 - r0, c1 - c0) * (1.0 + penalty[r1, c1])
    return total


def dijkstra_cost(penalty: np.ndarray, start, goal) -> float:
    """Reference: the cheapest cost with the same moves, by plain Dijkstra."""
    height, width = penalty.shape
    best = {start: 0.0}
    heap = [(0.0, start)]
    while heap:
        cost, (row, col) = heapq.heappop(heap)
        if (row, col) == goal:
            return cost
        if cost > best[(row, col)]:
            continue
        for d_row in (-1, 0, 1):
            for d_col in (-1, 0, 1):
                nxt = (row + d_row, col + d_col)
                if (d_row, d_col) == (0, 0) or not (0 <= nxt[0] < height and 0 <= nxt[1] < width):
                    continue
                if not math.isfinite(penalty[nxt]):
                    continue
                if d_row and d_col and not (math.isfinite(penalty[row + d_row, col])
                                            and math.isfinite(penalty[row, col + d_col])):
                    continue
                candidate = cost + math.hypot(d_row, d_col) * (1.0 + penalty[nxt])
                if candidate < best.get(nxt, math.inf):
                    best[nxt] = candidate
                    heapq.heappush(heap, (candidate, nxt))
    return math.inf


def test_astar_on_free_cells_takes_the_octile_distance():
    cells = astar(np.zeros((6, 8)), (0, 0), (3, 7))
    assert cells[0] == (0, 0) and cells[-1] == (3, 7)
    assert path_cost(np.zeros((6, 8)), cells) == pytest.approx(3 * math.sqrt(2) + 4)


@pytest.mark.parametrize('seed', range(5))
def test_astar_is_cost_optimal(seed):
    rng = np.random.default_rng(seed)
    penalty = rng.uniform(0.0, 3.0, (14, 14))
    penalty[rng.random((14, 14)) < 0.25] = np.inf
    penalty[0, 0] = penalty[13, 13] = 0.0
    cells = astar(penalty, (0, 0), (13, 13))
    expected = dijkstra_cost(penalty, (0, 0), (13, 13))
    if math.isinf(expected):
        assert cells is None
    else:
        assert all(math.isfinite(penalty[cell]) for cell in cells)
        steps = np.abs(np.diff(np.array(cells), axis=0))
        assert steps.max() <= 1
        assert path_cost(penalty, cells) == pytest.approx(expected)


def test_astar_never_cuts_a_corner():
    penalty = np.zeros((2, 2))
    penalty[0, 1] = penalty[1, 0] = np.inf
    assert astar(penalty, (0, 0), (1, 1)) is None
    penalty = np.zeros((3, 3))
    penalty[1, 0] = np.inf  # a diagonal step past this cell would clip its corner
    cells = astar(penalty, (0, 0), (2, 1))
    assert (1, 0) not in cells
    for (r0, c0), (r1, c1) in zip(cells, cells[1:]):
        if r0 != r1 and c0 != c1:
            assert math.isfinite(penalty[r1, c0]) and math.isfinite(penalty[r0, c1])


def test_astar_rejects_ends_outside_or_impassable():
    penalty = np.zeros((3, 3))
    penalty[2, 2] = np.inf
    with pytest.raises(ValueError, match='outside'):
        astar(penalty, (0, 0), (5, 0))
    with pytest.raises(ValueError, match='impassable'):
        astar(penalty, (0, 0), (2, 2))


def test_path_keeps_to_the_middle_of_a_corridor_and_off_the_walls():
    # A 2 m wide corridor (4 cells) between walls, 8 m long.
    rows = ['#' * 18] + ['#' + '.' * 16 + '#'] * 4 + ['#' * 18]
    costmap = Costmap(grid_map(rows), COSTMAP)
    path = plan_path(costmap, (1.0, 0.8), (8.0, 2.2), PLANNER)
    assert np.allclose(path.points[0], (1.0, 0.8)) and np.allclose(path.points[-1], (8.0, 2.2))
    # Away from the ends (the start is 0.3 m from a wall), it keeps the wanted clearance.
    inner = (path.arc_length > 1.0) & (path.arc_length < path.length - 1.0)
    assert costmap.clearance_at(path.points[inner]).min() >= 0.35 - 1e-6
    middle = path.points[(path.points[:, 0] > 3.5) & (path.points[:, 0] < 5.5)]
    assert np.all(np.abs(middle[:, 1] - 1.5) < 0.25)  # along the centre line


def test_path_goes_around_a_pillar_with_clearance():
    rows = ['##########',
            '#........#',
            '#........#',
            '#...##...#',
            '#...##...#',
            '#........#',
            '#........#',
            '##########']
    costmap = Costmap(grid_map(rows), COSTMAP)
    path = plan_path(costmap, (1.0, 2.0), (4.0, 2.0), PLANNER)
    # At least the wanted clearance less the smoothing allowance.
    assert costmap.clearance_at(path.points).min() >= 0.35 - 1e-6
    steps = np.hypot(*np.diff(path.points, axis=0).T)
    assert steps.max() <= PLANNER.spacing + 1e-9
    straight = 3.0
    assert straight < path.length < 2.0 * straight
    # Smoothing leaves no kinks: heading changes between points stay small.
    headings = np.unwrap(np.arctan2(*np.diff(path.points, axis=0).T[::-1]))
    assert np.abs(np.diff(headings)).max() < 0.35


def test_a_robot_touching_a_wall_still_gets_a_path_out():
    rows = ['#######', '#.....#', '#.....#', '#.....#', '#######']
    costmap = Costmap(grid_map(rows), COSTMAP)
    start = (0.62, 1.25)  # 0.12 m from the wall: inside the lethal radius
    path = plan_path(costmap, start, (2.5, 1.25), PLANNER)
    assert np.allclose(path.points[0], start)
    assert costmap.clearance_at(path.points[-10:]).min() > 0.25


def test_no_path_raises_a_planning_error():
    rows = ['#########', '#...#...#', '#...#...#', '#########']
    costmap = Costmap(grid_map(rows), COSTMAP)
    with pytest.raises(PlanningError, match='no path'):
        plan_path(costmap, (1.0, 1.0), (3.0, 1.0), PLANNER)
    near_only = PlannerConfig(spacing=0.05, wanted_clearance=0.5, escape_radius=0.2)
    with pytest.raises(PlanningError, match='goal'):
        plan_path(costmap, (1.0, 1.0), (2.25, 1.0), near_only)  # inside the wall


def test_path_curvature_of_a_circle():
    angles = np.linspace(0.0, math.pi, 200)
    points = np.stack((2.0 * np.cos(angles), 2.0 * np.sin(angles)), axis=1)
    path = Path.from_points(points, curvature_window=0.3)
    assert path.length == pytest.approx(2.0 * math.pi, rel=1e-3)
    assert np.allclose(path.curvature, 0.5, rtol=0.02)
    assert np.allclose(Path.from_points(points[::-1]).curvature, -0.5, rtol=0.02)
    assert np.allclose(path.point_at(path.length / 2), (0.0, 2.0), atol=1e-3)
