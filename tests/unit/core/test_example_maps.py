"""The shipped example maps: shape, feasibility and the features the scenarios need."""

import numpy as np
import pytest

from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import (
    certify_environment,
    footprint_free_mask,
    inflate,
    make_environment,
    reachable_regions,
    shortest_path_in_free,
)

pytestmark = pytest.mark.unit

SCENARIO_NAMES = ('factory', 'racetrack', 'drone')


@pytest.mark.parametrize('name', SCENARIO_NAMES)
def test_example_is_feasible_with_a_long_route(name):
    token_map = load_example_map(name)
    environment = make_environment(token_map.cells, name, f'{name}-example')
    environment.validate()
    assert environment.feasible
    height, width = token_map.cells.shape
    # Start and goal are at least half the map's side apart along the route.
    assert environment.route_length >= 0.5 * min(height, width) * environment.resolution
    # The whole free space of the example is one region for its robot.
    regions = reachable_regions(footprint_free_mask(token_map.cells, name))
    assert max(regions.sizes) >= 0.95 * sum(regions.sizes)


def test_racetrack_is_a_closed_circuit():
    cells = load_example_map('racetrack').cells
    environment = make_environment(cells, 'racetrack', 'example', seed=1)
    certificate = certify_environment(environment)
    route_free = certificate.grid.clearance >= certificate.required_clearance
    blocked_once = route_free.copy()
    for cell in certificate.path[1:-1]:
        blocked_once[cell] = False
    start, goal = certificate.path[0], certificate.path[-1]
    assert shortest_path_in_free(blocked_once, start, goal), (
        'the track must be a loop: a second way round from start to goal')
    # 3 to 7 cells wide: every track cell lies within 4 cells of out-of-bounds.
    track = cells == 0
    assert not inflate(track, 4.0).any()
    assert 0.1 < track.mean() < 0.5
    # Dense: the circuit winds over the whole square, so few 8x8 windows are all out of
    # bounds (identical empty patches cap the uniqueness a faithful generator can reach).
    windows = np.lib.stride_tricks.sliding_window_view(track, (8, 8))
    assert (~windows.any(axis=(2, 3))).mean() < 0.15


def test_factory_has_narrow_passages():
    cells = load_example_map('factory').cells
    free = cells == 0
    # A one-cell gap: a free cell with walls on both sides (left/right or above/below).
    walls = ~np.pad(free, 1, constant_values=False)
    horizontal = walls[1:-1, :-2] & walls[1:-1, 2:]
    vertical = walls[:-2, 1:-1] & walls[2:, 1:-1]
    assert (free & (horizontal | vertical)).sum() >= 3


def test_drone_has_a_section_only_the_drone_reaches():
    cells = load_example_map('drone').cells
    spec = get_scenario('drone')
    flyer = reachable_regions(footprint_free_mask(cells, 'drone'))
    on_ground = inflate(cells == 0, spec.robot_radius / spec.cell_size)
    walker = reachable_regions(on_ground)
    assert max(flyer.sizes) > max(walker.sizes) + 10
    assert (cells == 2).sum() >= 40 and (cells == 1).sum() >= 150
