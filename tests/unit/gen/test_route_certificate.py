"""Valid tests: start/goal clearance, the route certificate and its determinism."""

import dataclasses

import numpy as np
import pytest

from sessgan_core.grid_search import bfs, flat_grid
from sessgan_core.route_certificate import (
    bottleneck_clearance,
    certificate_subdivision,
    clearance_field,
    map_clearance,
    place_start_goal,
    required_clearances,
    track_length_steps,
)
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import tokens_to_occupancy
from sessgan_core.valid_tests import certify_environment, make_environment
from sessgan_gen.environment_sampler import EnvironmentSampler

pytestmark = pytest.mark.unit

SEEDS = range(900_000, 900_200)
MAPS = {'factory': 200, 'drone': 200, 'racetrack': 60}
"""Maps sampled per scenario: a race track costs about eight times a factory map to sample
and certify."""


def brute_clearance(occupancy, resolution, x, y, allowed):
    """Distance from (x, y) to the nearest blocked cell square or the grid's outside."""
    height, width = occupancy.shape
    edge = min(x, y, width * resolution - x, height * resolution - y)
    rows, cols = np.nonzero(~np.isin(occupancy, allowed))
    if not len(rows):
        return edge
    dx = np.maximum.reduce([cols * resolution - x, x - (cols + 1) * resolution, 0 * cols])
    dy = np.maximum.reduce([rows * resolution - y, y - (rows + 1) * resolution, 0 * rows])
    return min(edge, float(np.hypot(dx, dy).min()))


@pytest.fixture(scope='module')
def sampled():
    sampler = EnvironmentSampler()
    return {name: sampler.sample(list(SEEDS)[:count], scenario=name)
            for name, count in MAPS.items()}


@pytest.mark.parametrize('name', ['factory', 'drone', 'racetrack'])
def test_valid_tests_over_generated_maps(sampled, name):
    spec = get_scenario(name)
    place_need, route_need = required_clearances(spec)
    allowed = sorted({spec.occupancy[token] for token in spec.traversable})
    environments = sampled[name]
    valid = [environment for environment in environments if environment.feasible]
    assert len(valid) >= 0.8 * len(environments)
    for environment in valid:
        for pose in (environment.start, environment.goal):
            clearance = brute_clearance(environment.occupancy, environment.resolution,
                                        pose.x, pose.y, allowed)
            assert clearance >= place_need - 1e-9, (environment.id, pose, clearance)
        certificate = certify_environment(environment)
        assert certificate is not None, environment.id
        grid = certificate.grid
        assert all(grid.clearance[cell] >= route_need - 1e-9 for cell in certificate.path)
        steps = zip(certificate.path, certificate.path[1:], strict=False)
        assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in steps)
        assert environment.route_min_clearance >= route_need - 1e-9
        half_side = 0.5 * min(environment.occupancy.shape) * environment.resolution
        assert environment.route_length >= 0.5 * half_side  # taut line, not cell steps
    for environment in environments:
        if not environment.feasible:
            assert environment.extra['rejection'] in ('no_clear_cell', 'no_far_goal')


def test_placement_is_deterministic_per_seed(sampled):
    sampler = EnvironmentSampler()
    again = sampler.sample(list(SEEDS)[:20], scenario='factory')
    for first, second in zip(sampled['factory'][:20], again, strict=True):
        assert (first.start, first.goal, first.route_length) == (
            second.start, second.goal, second.route_length)
    starts = {(e.start.x, e.start.y) for e in sampled['factory']}
    assert len(starts) > 100  # drawn from the seed, not one fixed corner


def test_clearance_field_is_exact():
    rng = np.random.default_rng(3)
    blocked = rng.random((9, 11)) < 0.25
    grid = clearance_field(blocked, 0.5, 4, cap=3.0)
    occupancy = np.where(blocked, 100, 0)
    for row, col in [(0, 0), (5, 17), (20, 30), (35, 43), (17, 2)]:
        x, y = grid.centre((row, col))
        expected = min(brute_clearance(occupancy, 0.5, x, y, [0]), 3.0)
        assert grid.clearance[row, col] == pytest.approx(expected)


def test_a_one_metre_corridor_is_passable_for_the_factory_robot():
    # At cell-centre resolution a 2-cell corridor would show 0.25 m of clearance; the
    # certificate grid sees its 0.44 m.
    occupancy = np.full((8, 32), 100, dtype=np.int8)
    occupancy[3:5, :] = 0
    occupancy[1:7, :6] = 0
    occupancy[1:7, -6:] = 0
    environment = make_environment(np.where(occupancy == 100, 1, 0), 'factory', 'corridor')
    assert environment.feasible
    assert environment.route_min_clearance == pytest.approx(0.4375)
    assert certificate_subdivision(get_scenario('factory')) == 4


def test_bottleneck_is_the_tightest_unavoidable_passage():
    clearance = np.array([[1.0, 1.0, 1.0, 1.0],
                          [1.0, 0.2, 0.2, 1.0],
                          [1.0, 0.5, 0.3, 1.0],
                          [1.0, 1.0, 1.0, 1.0]])
    assert bottleneck_clearance(clearance, (0, 0), (3, 3), 0.0) == 1.0
    clearance[1:3, :] = [[0.2, 0.6, 0.3, 0.2], [0.2, 0.4, 0.3, 0.2]]
    assert bottleneck_clearance(clearance, (0, 0), (3, 3), 0.0) == 0.4
    # Cells below the floor are never entered: the wall of 0.2 around the sides cuts it.
    assert bottleneck_clearance(clearance, (0, 0), (3, 3), 0.35) == 0.4
    assert bottleneck_clearance(clearance, (0, 0), (3, 3), 0.45) == 0.0
    assert bottleneck_clearance(clearance, (1, 1), (3, 3), 0.0) == 0.4  # starts in the gap
    assert bottleneck_clearance(clearance, (0, 0), (1, 0), 0.5) == 0.0  # goal below floor
    assert bottleneck_clearance(clearance, (2, 1), (2, 1), 0.0) == 0.4


def serpentine_track(size=64):
    """A racetrack token map: one 5-cell road winding through four straights, about 270 m
    long on a 64 m map (track 0, out of bounds 1)."""
    cells = np.ones((size, size), dtype=np.int64)
    for row in (4, 20, 36, 52):
        cells[row:row + 5, 4:size - 4] = 0
    cells[4:25, size - 9:size - 4] = 0
    cells[20:41, 4:9] = 0
    cells[36:57, size - 9:size - 4] = 0
    return cells


def test_track_length_is_the_longest_route_between_clear_points():
    spec = get_scenario('racetrack')
    occupancy = tokens_to_occupancy(serpentine_track(32), spec)
    grid = map_clearance(occupancy, spec.cell_size, (0.0, 0.0), spec)
    place_need, route_need = required_clearances(spec)
    flat = flat_grid(grid.clearance >= route_need - 1e-9)
    rows, cols = np.nonzero(grid.clearance >= place_need - 1e-9)
    candidates = (rows + 1) * flat.stride + cols + 1
    region = [index for index, value in enumerate(flat.open_cells) if value]
    longest = 0
    for source in candidates.tolist():  # brute force: every pair of clear points
        dist = [-1] * len(flat.open_cells)
        bfs(flat, source, dist)
        longest = max(longest, int(np.asarray(dist)[candidates].max()))
    assert track_length_steps(flat, region, candidates) == longest
    assert track_length_steps(flat, region, candidates[:0]) == 0


def test_race_track_goals_lie_half_the_track_length_along_the_route():
    spec = get_scenario('racetrack')
    assert spec.goal_track_fraction == 0.5
    assert get_scenario('factory').goal_track_fraction == 0.0
    assert get_scenario('drone').goal_track_fraction == 0.0
    occupancy = tokens_to_occupancy(serpentine_track(), spec)
    grid = map_clearance(occupancy, spec.cell_size, (0.0, 0.0), spec)
    place_need, route_need = required_clearances(spec)
    flat = flat_grid(grid.clearance >= route_need - 1e-9)
    rows, cols = np.nonzero(grid.clearance >= place_need - 1e-9)
    region = [index for index, value in enumerate(flat.open_cells) if value]
    length = track_length_steps(flat, region, (rows + 1) * flat.stride + cols + 1)
    assert length * grid.cell_size > 200  # m: the road is one long path
    without = dataclasses.replace(spec, goal_track_fraction=0.0)
    apart, apart_without = [], []
    for seed in range(30):
        for rule, steps in ((spec, apart), (without, apart_without)):
            placement = place_start_goal(occupancy, spec.cell_size, (0.0, 0.0), rule, seed)
            assert placement.certificate is not None
            steps.append(len(placement.certificate.path) - 1)
    assert min(apart) >= 0.5 * length
    # Half the farthest point from the start alone lets a start mid-track take a goal a
    # quarter of the track away.
    assert min(apart_without) < 0.5 * length
    again = place_start_goal(occupancy, spec.cell_size, (0.0, 0.0), spec, 7)
    first = place_start_goal(occupancy, spec.cell_size, (0.0, 0.0), spec, 7)
    assert (again.start, again.goal) == (first.start, first.goal)
