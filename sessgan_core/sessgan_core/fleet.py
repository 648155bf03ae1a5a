"""Fleets: more robots under test in one world, each with its own start, goal and route.

Robot ``r0`` drives the environment's own start and goal, drawn and certified by
:func:`sessgan_core.route_certificate.place_start_goal`; robots ``r1``, ``r2``, ... are
drawn by :func:`place_fleet` from the same map seed on a random stream of their own, so a
one-robot map (:class:`FleetSpec` with ``robots=1``, the default) is exactly the plain
episode's. Every fleet robot follows the rules of start and goal (module
:mod:`sessgan_core.route_certificate`), and more:

* Its start and goal have the clearance start and goal need (``robot_radius +
  clearance_margin``), and lie at least :func:`separation` (two footprints with their
  margins) from every other robot's start and goal: no robot starts inside another or
  parks on another's goal.
* Its goal is far along its route (at least :func:`~sessgan_core.route_certificate.min_route_steps`
  and at least half as far as the farthest clear point); both yaws point along the route.
* A robot that arrives stays parked on its goal, so every robot's route (``r0``'s included)
  is certified with every *other* robot parked on its goal, a disc of the robot's radius.
  Starts are not obstacles: their robots drive away.

A map that cannot hold that many robots is not a valid test: :class:`FleetPlacement`'s
``rejection`` says why (a :class:`FleetRejection` value) and ``detail`` which robot.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from sessgan_core.environment import MAX_ROBOTS, FleetRobot, Pose2D
from sessgan_core.errors import InvalidFleetError
from sessgan_core.grid_search import bfs, flat_grid, steps_of, to_cell, to_flat, unvisited
from sessgan_core.route_certificate import (
    HEADING_LOOKAHEAD_M,
    START_TRIES,
    CertificateGrid,
    Placement,
    RouteCertificate,
    certify,
    map_clearance,
    min_route_steps,
    required_clearances,
)
from sessgan_core.scenarios import Scenario

FLEET_SEED_KEY = 0xF1EE
"""Spawn key of the fleet's random stream (start, goal and stations keep theirs)."""

Pose = tuple[float, float, float]
"""(x, y, yaw) in metres and radians, map frame."""
Cell = tuple[int, int]


class FleetRejection:
    """Why a fleet map is not a valid test, beyond the start and goal's own reasons."""

    NO_FLEET_ROOM = 'no_fleet_room'
    """No clear point is far enough from every other robot's start and goal."""
    NO_FLEET_ROUTE = 'no_fleet_route'
    """No draw gave a robot a far goal, apart from the others, on a certified route that
    keeps every other robot's route certified with it parked there."""


@dataclass(frozen=True)
class FleetSpec:
    """What a user asks for: how many robots under test share each map.

    The one place the ``robots`` parameter is validated; the generator node, the simulator's
    free mode and the campaign all build one from their parameters.
    """

    robots: int = 1
    """Robots under test, r0 included (1: one robot, the plain episode)."""

    def validate(self, mission_stations: int = 0) -> FleetSpec:
        """This spec, or InvalidFleetError naming what is wrong (a fleet with mission
        stations too: each fleet robot drives start -> goal)."""
        robots = self.robots
        if (not isinstance(robots, (int, np.integer)) or isinstance(robots, bool)
                or not 1 <= robots <= MAX_ROBOTS):
            raise InvalidFleetError(
                f'robots must be an integer in 1..{MAX_ROBOTS} (robots under test on every '
                f'map; 1: one robot), got {robots!r}')
        if robots > 1 and mission_stations:
            raise InvalidFleetError(
                f'robots={robots} cannot be combined with mission_stations='
                f'{mission_stations}: each robot of a fleet drives start -> goal')
        return self


class FleetPlacement(NamedTuple):
    """Starts, goals and routes of robots r1, r2, ..., or why there are none."""

    starts: tuple[Pose, ...]
    """Of robots r1, r2, ... (() when rejected or for one robot)."""
    goals: tuple[Pose, ...]
    routes: tuple[RouteCertificate, ...]
    """Every robot's certified route with the others parked on their goals, r0's first
    (r0's plain certificate for one robot; () when rejected)."""
    rejection: str
    """'' for a valid test, else a FleetRejection value."""
    detail: str
    """Which robot could not be placed, in words ('' for a valid test)."""

    def robots(self) -> tuple[FleetRobot, ...]:
        """The Environment's ``fleet``: robots r1, r2, ... with their route lengths."""
        return tuple(FleetRobot(Pose2D(*start), Pose2D(*goal), float(route.length))
                     for start, goal, route in zip(self.starts, self.goals, self.routes[1:]))


def separation(spec: Scenario) -> float:
    """m, the least distance between any two robots' starts and goals: two footprints,
    each with the clearance margin start and goal keep."""
    return 2.0 * (spec.robot_radius + spec.clearance_margin)


def with_parked(grid: CertificateGrid, points: Iterable[tuple[float, float]],
                radius: float) -> CertificateGrid:
    """The clearance field with a robot of ``radius`` parked at each map-frame point."""
    clearance = grid.clearance.copy()
    height, width = clearance.shape
    xs = grid.origin[0] + (np.arange(width) + 0.5) * grid.cell_size
    ys = grid.origin[1] + (np.arange(height) + 0.5) * grid.cell_size
    for x, y in points:
        gap = np.hypot(xs[None, :] - x, ys[:, None] - y) - radius
        np.minimum(clearance, np.maximum(gap, 0.0), out=clearance)
    return grid._replace(clearance=clearance)


def _joined(free: np.ndarray, start: Cell, goal: Cell) -> bool:
    """Whether two cells connect 4-connected through ``free``."""
    if not (free[start] and free[goal]):
        return False
    flat = flat_grid(free)
    dist = unvisited(flat)
    target = to_flat(flat, goal)
    bfs(flat, to_flat(flat, start), dist, target)
    return dist[target] >= 0


def _route_yaws(grid: CertificateGrid, path: list[Cell]) -> tuple[float, float]:
    """Yaws along the route's first and last HEADING_LOOKAHEAD_M (as place_start_goal)."""
    lookahead = max(1, min(len(path) - 1, round(HEADING_LOOKAHEAD_M / grid.cell_size)))

    def along(a: Cell, b: Cell) -> float:
        (x0, y0), (x1, y1) = grid.centre(a), grid.centre(b)
        return math.atan2(y1 - y0, x1 - x0) if (x0, y0) != (x1, y1) else 0.0

    return along(path[0], path[lookahead]), along(path[-1 - lookahead], path[-1])


def place_fleet(placement: Placement, spec: Scenario, seed: int,
                fleet: FleetSpec | None = None) -> FleetPlacement:
    """Draw robots r1..r(N-1) on the map of robot r0's certified ``placement`` (from
    :func:`~sessgan_core.route_certificate.place_start_goal`) from ``seed``, by the rules in
    the module docstring. Deterministic per (map, seed, robots); r0 is never moved."""
    fleet = (fleet or FleetSpec()).validate()
    if placement.start is None or placement.goal is None or placement.certificate is None:
        raise ValueError('place_fleet needs a placement with robot r0 placed and certified')
    if fleet.robots == 1:
        return FleetPlacement((), (), (placement.certificate,), '', '')
    grid = placement.certificate.grid
    place_need, route_need = required_clearances(spec)
    apart = separation(spec) - 1e-9
    shape = (grid.clearance.shape[0] // grid.subdivision,
             grid.clearance.shape[1] // grid.subdivision)
    min_steps = min_route_steps(shape, grid.subdivision)
    rows, cols = np.nonzero(grid.clearance >= place_need - 1e-9)
    xs = grid.origin[0] + (cols + 0.5) * grid.cell_size
    ys = grid.origin[1] + (rows + 0.5) * grid.cell_size
    # Robot k: (start cell, goal cell, goal point); r0 first.
    robots = [(placement.certificate.path[0], placement.certificate.path[-1],
               placement.goal[:2])]
    ends = [placement.start[:2], placement.goal[:2]]  # every start and goal placed so far
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(FLEET_SEED_KEY,)))
    for number in range(1, fleet.robots):
        free_of_ends = np.ones(len(rows), dtype=bool)
        for x, y in ends:
            free_of_ends &= np.hypot(xs - x, ys - y) >= apart
        # This robot drives among the others parked on their goals.
        routable = (with_parked(grid, (goal for _, _, goal in robots), spec.robot_radius)
                    .clearance >= route_need - 1e-9)
        usable = free_of_ends & routable[rows, cols]
        if not usable.any():
            return _rejected(FleetRejection.NO_FLEET_ROOM,
                             f'robot r{number}: no clear point at least {apart:.2f} m from '
                             f"every other robot's start and goal")
        flat = flat_grid(routable)
        candidates = ((rows + 1) * flat.stride + cols + 1)[usable]
        chosen = None
        for _ in range(START_TRIES):
            start = int(candidates[rng.integers(len(candidates))])
            dist = unvisited(flat)
            bfs(flat, start, dist)
            steps = steps_of(dist)[candidates]
            goals = candidates[steps >= max(min_steps, 0.5 * int(steps.max()))]
            if not len(goals):
                continue
            goal = int(goals[rng.integers(len(goals))])
            goal_xy = grid.centre(to_cell(flat, goal))
            start_xy = grid.centre(to_cell(flat, start))
            if math.dist(goal_xy, start_xy) < apart:
                continue
            # Parked on this goal, the robot must leave every earlier robot its route.
            if not all(_joined(with_parked(grid, [g for j, (_, _, g) in enumerate(robots)
                                                  if j != k] + [goal_xy],
                                           spec.robot_radius).clearance >= route_need - 1e-9,
                               other_start, other_goal)
                       for k, (other_start, other_goal, _) in enumerate(robots)):
                continue
            chosen = (to_cell(flat, start), to_cell(flat, goal), goal_xy, start_xy)
            break
        if chosen is None:
            return _rejected(FleetRejection.NO_FLEET_ROUTE,
                             f'robot r{number}: no far goal on a certified route that leaves '
                             f'the other {number} robots theirs ({START_TRIES} starts tried)')
        robots.append(chosen[:3])
        ends += [chosen[3], chosen[2]]
    routes = []
    for k, (start_cell, goal_cell, _) in enumerate(robots):
        parked = with_parked(grid, [g for j, (_, _, g) in enumerate(robots) if j != k],
                             spec.robot_radius)
        route = certify(parked, start_cell, goal_cell, route_need)
        if route is None:  # the draws above checked it; kept as a guard, not expected
            return _rejected(FleetRejection.NO_FLEET_ROUTE, f'robot r{k}: no certified route')
        routes.append(route)
    starts, goals = [], []
    for route in routes[1:]:
        start_yaw, goal_yaw = _route_yaws(grid, route.path)
        starts.append((*grid.centre(route.path[0]), start_yaw))
        goals.append((*grid.centre(route.path[-1]), goal_yaw))
    return FleetPlacement(tuple(starts), tuple(goals), tuple(routes), '', '')


def certify_robots(occupancy: np.ndarray, resolution: float, origin: tuple[float, float],
                   spec: Scenario, robots: list[tuple[tuple[float, float], tuple[float, float]]]
                   ) -> list[RouteCertificate | None]:
    """The certificate of every robot's (start, goal) map-frame points, r0 first, with the
    other robots parked on their goals; None for a robot without a certified route."""
    grid = map_clearance(occupancy, resolution, origin, spec)
    route_need = required_clearances(spec)[1]
    routes = []
    for k, (start, goal) in enumerate(robots):
        parked = with_parked(grid, [g for j, (_, g) in enumerate(robots) if j != k],
                             spec.robot_radius)
        routes.append(certify(parked, grid.cell_of(*start), grid.cell_of(*goal), route_need))
    return routes


def _rejected(rejection: str, detail: str) -> FleetPlacement:
    return FleetPlacement((), (), (), rejection, detail)


# ---- JSON (episode.json, run stores) -----------------------------------------------------

def fleet_to_json(fleet: Iterable[FleetRobot]) -> list[dict[str, Any]]:
    """An Environment's fleet as JSON data: [{'start': [x, y, yaw], 'goal': [...],
    'route_length': m}, ...] for robots r1, r2, ..."""
    return [{'start': [robot.start.x, robot.start.y, robot.start.yaw],
             'goal': [robot.goal.x, robot.goal.y, robot.goal.yaw],
             'route_length': float(robot.route_length)} for robot in fleet]


def fleet_from_json(data: Iterable[Mapping[str, Any]] | None) -> tuple[FleetRobot, ...]:
    """The fleet of :func:`fleet_to_json`'s data; None (a file from before fleets): none."""
    return tuple(FleetRobot(Pose2D(*robot['start']), Pose2D(*robot['goal']),
                            float(robot.get('route_length', 0.0))) for robot in data or ())
