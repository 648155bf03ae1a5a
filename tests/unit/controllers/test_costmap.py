"""The navigator's costmap: clearance (inflation), penalties and the scan overlay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import MapData, RobotState
from sessgan_controllers.costmap import Costmap, CostmapConfig, clearance_field

pytestmark = pytest.mark.unit


def config(**overrides) -> CostmapConfig:
    values = dict(robot_radius=0.2, safety_margin=0.05, inflation_radius=0.5,
                  cost_scaling_factor=6.0, cost_weight=3.0, inscribed_penalty=50.0,
                  resolution=0.1)
    values.update(overrides)
    return CostmapConfig(**values)


def grid_map(rows: list[str], resolution: float = 0.5) -> MapData:
    """'#' wall (100), 'o' low obstacle (50), '?' unknown (-1), '.' free; first row on top."""
    values = {'.': 0, '#': 100, 'o': 50, '?': -1}
    occupancy = np.array([[values[char] for char in row] for row in reversed(rows)],
                         dtype=np.int8)
    return MapData(occupancy, resolution, (0.0, 0.0))


def test_clearance_is_the_distance_to_the_nearest_blocked_square():
    blocked = np.zeros((5, 5), dtype=bool)
    blocked[2, 2] = True
    distance = clearance_field(blocked, 1.0, 10.0)
    assert distance[2, 2] == 0.0
    assert distance[2, 3] == pytest.approx(0.5)  # to the square's edge, not its centre
    assert distance[3, 3] == pytest.approx(math.hypot(0.5, 0.5))
    assert distance[2, 0] == pytest.approx(0.5)  # the grid's outside is blocked too
    capped = clearance_field(np.zeros((9, 9), dtype=bool), 1.0, 2.0)
    assert capped[4, 4] == pytest.approx(2.0)


def test_map_cells_are_split_to_the_planning_resolution():
    costmap = Costmap(grid_map(['...', '.#.', '...']), config())
    assert costmap.factor == 5 and costmap.resolution == pytest.approx(0.1)
    assert costmap.shape == (15, 15)
    assert costmap.blocked[5:10, 5:10].all() and costmap.blocked.sum() == 25
    # A fine cell next to the wall cell: its centre is half a fine cell from the wall.
    assert costmap.static_clearance[7, 10] == pytest.approx(0.05)


def test_penalty_zones_follow_nav2_inflation():
    costmap = Costmap(grid_map(['........', '........', '........', '###.....']), config())
    clearance = np.array([0.1, 0.2, 0.22, 0.25, 0.3, 0.5, 0.74, 0.75, 1.0])
    penalty = costmap.penalty_of(clearance)
    assert math.isinf(penalty[0])                                # footprint touches
    assert penalty[1] == penalty[2] == 50.0                      # inscribed band
    assert penalty[3] == pytest.approx(3.0)                      # inner edge of the decay
    assert penalty[4] == pytest.approx(3.0 * math.exp(-6.0 * 0.05))
    assert penalty[3] > penalty[4] > penalty[5] > penalty[6] > 0.0
    assert penalty[7] == penalty[8] == 0.0                       # beyond the inflation


def test_low_obstacles_are_passable_only_for_a_flyer_and_unknown_is_blocked():
    rows = ['.....', '.o.?.', '.....']
    ground = Costmap(grid_map(rows), config())
    flyer = Costmap(grid_map(rows), config(passable_values=(0, 50)))
    low_cell = (7, 7)  # the centre of map cell (1, 1) at 5 sub-cells per cell
    unknown_cell = (7, 17)
    assert ground.blocked[low_cell] and not flyer.blocked[low_cell]
    assert ground.blocked[unknown_cell] and flyer.blocked[unknown_cell]


def test_clearance_at_interpolates_between_cell_centres():
    costmap = Costmap(grid_map(['#....', '#....', '#....']), config())
    # x measured from the wall's face at x = 0.5 m.
    for x in (0.6, 0.75, 0.83):
        assert costmap.clearance_at(np.array([[x, 0.75]]))[0] == pytest.approx(x - 0.5, abs=1e-9)
    assert costmap.clearance_at(np.array([[-1.0, 0.75]]))[0] == 0.0  # outside the grid


def test_returns_the_map_does_not_explain_are_marked_and_walls_are_not(scan_factory):
    rows = ['##########'] + ['#........#'] * 6 + ['##########']
    costmap = Costmap(grid_map(rows), config())
    state = RobotState(1.0, 1.0, 0.0)
    wall_scan = scan_factory(state, grid=rows, range_max=6.0)
    assert costmap.update_marks(wall_scan, state) is False
    assert not costmap.marks
    disc_scan = scan_factory(state, grid=rows, discs=[(2.5, 1.0, 0.2)], range_max=6.0)
    assert costmap.update_marks(disc_scan, state) is True
    assert costmap.marks
    marked = costmap.centres(*np.array(list(costmap.marks)).T)
    assert np.all(np.hypot(marked[:, 0] - 2.5, marked[:, 1] - 1.0) < 0.35)
    # The marks make cells near the disc lethal for the footprint.
    row, col = costmap.cell_of(2.2, 1.0)
    assert math.isinf(costmap.penalty[row, col])
    assert math.isfinite(costmap.penalty[costmap.cell_of(1.0, 2.5)])


def test_a_beam_through_a_mark_clears_it(scan_factory):
    rows = ['##########'] + ['#........#'] * 6 + ['##########']
    costmap = Costmap(grid_map(rows), config())
    state = RobotState(1.0, 1.0, 0.0)
    costmap.update_marks(scan_factory(state, grid=rows, discs=[(2.5, 1.0, 0.2)]), state)
    assert costmap.marks
    # The disc moved away: beams now reach the far wall through its old place.
    assert costmap.update_marks(scan_factory(state, grid=rows), state) is True
    assert not costmap.marks
    row, col = costmap.cell_of(2.2, 1.0)
    assert math.isfinite(costmap.penalty[row, col])


def test_a_hidden_mark_expires_after_its_lifetime(scan_factory):
    rows = ['##########'] + ['#........#'] * 6 + ['##########']
    costmap = Costmap(grid_map(rows), config(mark_lifetime=3))
    state = RobotState(1.0, 1.0, 0.0)
    costmap.update_marks(scan_factory(state, grid=rows, discs=[(3.5, 1.0, 0.2)]), state)
    assert costmap.marks
    # Something nearer now hides the old marks from every beam that could clear them, and
    # stands outside the marking range.
    hidden = scan_factory(state, grid=rows, discs=[(1.6, 1.0, 0.1)])
    far = Costmap(grid_map(rows), config(mark_lifetime=3, mark_range=0.3))
    far.marks = dict(costmap.marks)
    for _ in range(3):
        far.update_marks(hidden, state)
    assert far.marks
    far.update_marks(hidden, state)
    assert not far.marks
