"""Footprint-aware free space, valid-test environments and shortest paths.

Used by the generator, the simulator and the evolver, so everything here is
deterministic (random choices come from the environment's seed) and fast: the evolver
builds thousands of environments per generation.

Conventions:

* Cells are ``(row, col)`` in OccupancyGrid order (row 0 = lowest y).
* **Footprint inflation** (:func:`inflate`): the robot's centre may stand on a cell when no
  blocked cell *square* comes closer than the robot's radius to the cell's centre, and the
  grid's outside counts as blocked. Agents use it to patrol.
* **Valid tests** (:func:`make_environment`): start, goal and the route certificate come from
  :mod:`sessgan_core.route_certificate` (start and goal with clearance, a route that keeps a
  safety margin, far apart along it).
* **Connectivity**: 4-connected moves only (sessgan_core.grid_search).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from sessgan_core.environment import Environment, FleetRobot, Pose2D
from sessgan_core.fleet import FleetSpec, certify_robots, place_fleet
from sessgan_core.grid_search import (
    FlatGrid,
    bfs_continue,
    flat_grid,
    label_regions,
    to_cell,
    to_flat,
    unvisited,
    walk_back,
)
from sessgan_core.missions import MissionSpec, certify_legs, place_mission
from sessgan_core.route_certificate import (
    RouteCertificate,
    certify,
    map_clearance,
    required_clearances,
)
from sessgan_core.scenarios import Scenario
from sessgan_core.token_map import ScenarioLike, check_cells, resolve_scenario, tokens_to_occupancy
from sessgan_core.validation import require_non_negative

Cell = tuple[int, int]
"""A grid cell (row, col)."""

OPEN_CELL_WINDOW = 5
"""Side in cells of the window counting passable cells to find the most open cell."""


class Regions(NamedTuple):
    """4-connected regions of a free mask."""

    labels: np.ndarray
    """int32 array, region index of each free cell, -1 elsewhere; regions numbered in
    row-major order of their first cell."""
    sizes: list[int]
    """Number of cells of each region."""


def passable_mask(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Cells the robot may occupy (its tokens in ``scenario.traversable``), as a bool array."""
    spec = resolve_scenario(scenario)
    array = check_cells(cells, spec)
    table = np.zeros(spec.num_tokens, dtype=bool)
    table[list(spec.traversable)] = True
    return table[array]


def occupancy_passable_mask(occupancy: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Passable cells of an OccupancyGrid array (e.g. an Environment's) for a scenario's robot.

    A cell is passable when its value is the occupancy of one of the scenario's
    traversable tokens (free 0; also low obstacle 50 for the drone). Unknown (-1)
    and any other value are not passable.
    """
    spec = resolve_scenario(scenario)
    allowed = sorted({spec.occupancy[token] for token in spec.traversable})
    return np.isin(np.asarray(occupancy), allowed)


@lru_cache(maxsize=64)
def _footprint_offsets(radius_cells: float) -> tuple[tuple[int, int], ...]:
    """Return the precomputed disc kernel of :func:`inflate`.

    Offsets (dr, dc), other than (0, 0), of the cells whose square lies closer than
    ``radius_cells`` to a cell centre.
    """
    reach = int(math.ceil(radius_cells + 0.5))
    offsets = []
    for d_row in range(-reach, reach + 1):
        for d_col in range(-reach, reach + 1):
            if d_row == 0 and d_col == 0:
                continue
            gap = math.hypot(max(abs(d_row) - 0.5, 0.0), max(abs(d_col) - 0.5, 0.0))
            if gap < radius_cells:
                offsets.append((d_row, d_col))
    return tuple(offsets)


def inflate(passable: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells where a disc of ``radius_cells`` (in cells) centred on the cell touches nothing.

    A cell is free for the footprint when it is passable and no blocked cell's
    square, nor the outside of the grid, lies closer than ``radius_cells`` to its
    centre. Returns a new bool array of the same shape.
    """
    mask = np.asarray(passable, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f'passable mask must be 2-D, got shape {mask.shape}')
    require_non_negative('radius', radius_cells, unit=' cells')
    offsets = _footprint_offsets(round(float(radius_cells), 9))
    blocked = ~mask
    if not offsets:
        return mask.copy()
    reach = max(max(abs(d_row), abs(d_col)) for d_row, d_col in offsets)
    height, width = mask.shape
    padded = np.pad(blocked, reach, mode='constant', constant_values=True)
    out = blocked.copy()
    for d_row, d_col in offsets:
        out |= padded[reach + d_row:reach + d_row + height, reach + d_col:reach + d_col + width]
    return ~out


def footprint_free_mask(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Cells where the scenario's robot centre may stand: passable cells, inflated."""
    spec = resolve_scenario(scenario)
    return inflate(passable_mask(cells, spec), spec.robot_radius / spec.cell_size)


def reachable_regions(free: np.ndarray) -> Regions:
    """The 4-connected regions of a free mask (e.g. :func:`footprint_free_mask`)."""
    grid = flat_grid(free)
    regions = label_regions(grid)
    label_array = regions.labels.reshape(-1, grid.stride)[1:-1, 1:-1]
    return Regions(np.ascontiguousarray(label_array), regions.sizes.tolist())


def _check_cell(free: np.ndarray, cell: Cell, label: str) -> None:
    row, col = cell
    if not (0 <= row < free.shape[0] and 0 <= col < free.shape[1]):
        raise ValueError(f'{label} cell {cell} lies outside the {free.shape[1]}x'
                         f'{free.shape[0]} grid')


def shortest_path_in_free(free: np.ndarray, start: Cell, goal: Cell) -> list[Cell]:
    """4-connected shortest path from ``start`` to ``goal`` inside a free mask.

    Both ends are included; [] when either end is not free or no path exists.
    """
    return shortest_paths_from(free, start)(goal)


def shortest_paths_from(free: np.ndarray, start: Cell, grid: FlatGrid | None = None
                        ) -> Callable[[Cell], list[Cell]]:
    """shortest_path_in_free(free, start, goal) for any goal, searching from start once
    (``grid``: ``free``'s flat_grid, when the caller has it). The search goes only as far
    as the goals asked so far need (grid_search.bfs: the same paths as a full search)."""
    mask = np.asarray(free, dtype=bool)
    _check_cell(mask, start, 'start')
    grid = flat_grid(mask) if grid is None else grid
    dist = unvisited(grid)
    queue = [to_flat(grid, start)] if mask[start] else []
    head = 0  # queue[head:] is still to expand
    if queue:
        dist[queue[0]] = 0

    def path_to(goal: Cell) -> list[Cell]:
        nonlocal head
        _check_cell(mask, goal, 'goal')
        if not (mask[start] and mask[goal]):
            return []
        target = to_flat(grid, goal)
        head = bfs_continue(grid, dist, queue, head, target)
        if dist[target] < 0:
            return []
        return [to_cell(grid, index) for index in walk_back(grid, dist, target)]
    return path_to


def certify_environment(environment: Environment) -> RouteCertificate | None:
    """The route certificate of an Environment's own start and goal (None: not a valid test).

    Recomputed from the occupancy grid with the scenario's margins, so it also holds for
    environments that did not come from :func:`make_environment` (a user's map, a bag).
    """
    spec = resolve_scenario(environment.scenario)
    grid = map_clearance(environment.occupancy, environment.resolution, environment.origin,
                         spec)
    start = grid.cell_of(environment.start.x, environment.start.y)
    goal = grid.cell_of(environment.goal.x, environment.goal.y)
    return certify(grid, start, goal, required_clearances(spec)[1])


def certify_mission(environment: Environment) -> list[RouteCertificate | None]:
    """The certificate of every leg of an Environment's mission (start -> stations -> goal;
    one leg for a plain episode), None for a leg without a certified route. Recomputed from
    the grid like :func:`certify_environment`."""
    points = [(pose.x, pose.y) for pose in (environment.start, *environment.waypoints)]
    return certify_legs(environment.occupancy, environment.resolution, environment.origin,
                        resolve_scenario(environment.scenario), points)


def certify_fleet(environment: Environment) -> list[RouteCertificate | None]:
    """The certificate of every robot's route, r0 (start -> goal) first, each with the other
    robots parked on their goals (sessgan_core.fleet); None for a robot without one.
    Recomputed from the grid like :func:`certify_environment`."""
    robots = [((environment.start.x, environment.start.y),
               (environment.goal.x, environment.goal.y))]
    robots += [((robot.start.x, robot.start.y), (robot.goal.x, robot.goal.y))
               for robot in environment.fleet]
    return certify_robots(environment.occupancy, environment.resolution, environment.origin,
                          resolve_scenario(environment.scenario), robots)


def environment_is_feasible(environment: Environment) -> bool:
    """Whether every leg of an Environment's mission (for a plain episode: start to goal) has
    a certified route; for a fleet, every robot's route among the others parked."""
    if environment.fleet:
        return all(route is not None for route in certify_fleet(environment))
    if not environment.stations:
        return certify_environment(environment) is not None
    return all(leg is not None for leg in certify_mission(environment))


def _box_sums(mask: np.ndarray, side: int) -> np.ndarray:
    """Number of True cells in the side x side window centred on each cell (side odd)."""
    half = side // 2
    padded = np.pad(mask.astype(np.int32), half)
    summed = np.pad(padded.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    height, width = mask.shape
    return (summed[side:side + height, side:side + width] - summed[:height, side:side + width]
            - summed[side:side + height, :width] + summed[:height, :width])


def most_open_cell(cells: np.ndarray, scenario: ScenarioLike) -> Cell:
    """Return the most open cell, the fallback pose of maps without a feasible route.

    Footprint-free cells come first, then passable ones; among those, the most passable
    cells in the OPEN_CELL_WINDOW square, then in the 3 x 3 square; ties go to the
    smallest (row, col).
    """
    spec = resolve_scenario(scenario)
    passable = passable_mask(cells, spec)
    free = inflate(passable, spec.robot_radius / spec.cell_size)
    wide = _box_sums(passable, OPEN_CELL_WINDOW)
    near = _box_sums(passable, 3)
    # Each term outweighs all the later ones: near <= 9 < 10, 10 * wide + near < 1000.
    score = free * 100_000 + passable * 10_000 + wide * 10 + near
    row, col = np.unravel_index(int(np.argmax(score)), score.shape)
    return (int(row), int(col))


def make_environment(cells: np.ndarray, scenario_name: ScenarioLike, env_id: str,
                     seed: int = 0, generation: int = -1, member: int = -1,
                     mission: MissionSpec | None = None,
                     fleet: FleetSpec | None = None,
                     origin: tuple[float, float] = (0.0, 0.0)) -> Environment:
    """Build the Environment of a token map: occupancy, start, goal and route certificate.

    Resolution is the scenario's cell size (metres per cell) and ``origin`` the map-frame
    position of cell (0, 0)'s corner, so cell (row, col) spans x in [origin_x + col*res,
    origin_x + (col+1)*res); every pose is in that frame (a facility generator's maps sit at
    its training map's origin, sessgan_gen.checkpoint.map_origin). Start and goal are drawn
    from ``seed`` by
    :func:`sessgan_core.route_certificate.place_start_goal`; ``feasible`` (a valid test) is
    True when they exist, with ``route_length`` and ``route_min_clearance`` (the bottleneck
    clearance) in metres. Otherwise start and goal both sit at :func:`most_open_cell`, yaw 0,
    and ``extra['rejection']`` says why. ``extra`` also holds the start and goal clearances.

    ``mission`` (sessgan_core.missions) asks for stations before home: they are drawn from
    the seed too, every leg certified; ``route_length`` is then the legs' total, and
    ``route_min_clearance`` the tightest leg's (``extra['leg_route_lengths']`` per leg). An
    infeasible mission keeps no stations. Without stations the Environment is the plain
    episode's, exactly.

    ``fleet`` (sessgan_core.fleet) asks for more robots under test: robots r1, r2, ... are
    drawn from the seed around the plain episode's start and goal (robot r0's), every route
    certified with the other robots parked on their goals; ``route_length`` is then r0's
    route among them and ``route_min_clearance`` the tightest robot's. A map that cannot
    hold them all is not feasible (``extra['rejection']`` and ``extra['rejection_detail']``)
    and keeps no fleet. With one robot the Environment is the plain episode's, exactly.
    """
    spec: Scenario = resolve_scenario(scenario_name)
    mission = (mission or MissionSpec()).validate()
    fleet = (fleet or FleetSpec()).validate(mission.stations)
    array = check_cells(cells, spec)
    occupancy = tokens_to_occupancy(array, spec)
    resolution = spec.cell_size
    origin = (float(origin[0]), float(origin[1]))
    drawn = place_mission(occupancy, resolution, origin, spec, seed, mission)
    placement = drawn.placement
    extra: dict = {'start_clearance': placement.start_clearance,
                   'goal_clearance': placement.goal_clearance,
                   'rejection': drawn.rejection}
    stations: tuple[Pose2D, ...] = ()
    if drawn.start is None or drawn.goal is None:
        row, col = most_open_cell(array, spec)
        start = goal = Pose2D(origin[0] + (col + 0.5) * resolution,
                              origin[1] + (row + 0.5) * resolution, 0.0)
        feasible, length, bottleneck = False, 0.0, 0.0
    else:
        start, goal = Pose2D(*drawn.start), Pose2D(*drawn.goal)
        stations = tuple(Pose2D(*station) for station in drawn.stations)
        feasible = True
        length, bottleneck = drawn.route_length, drawn.bottleneck_clearance
        if stations:
            extra['leg_route_lengths'] = [leg.length for leg in drawn.legs]
    robots: tuple[FleetRobot, ...] = ()
    if feasible and fleet.robots > 1:
        placed = place_fleet(placement, spec, seed, fleet)
        if placed.rejection:
            feasible = False
            extra['rejection'] = placed.rejection
            extra['rejection_detail'] = placed.detail
        else:
            robots = placed.robots()
            length = placed.routes[0].length
            bottleneck = min(route.bottleneck_clearance for route in placed.routes)
    return Environment(
        id=env_id, scenario=spec.name, occupancy=occupancy, resolution=resolution,
        start=start, goal=goal, origin=origin, seed=seed, generation=generation,
        member=member, feasible=feasible, route_length=length,
        route_min_clearance=bottleneck, extra=extra, stations=stations,
        dwell_time=float(mission.dwell_time) if stations else 0.0, fleet=robots)
