"""Pick-up and place missions: stations drawn from the map seed, every leg certified.

A mission is the sequence of waypoints an episode's robot visits: ``stations`` (pick-up,
place, ...) and then home, the start pose it left from, with a dwell (loading) of
``dwell_time`` seconds standing still at each station. A plain start -> goal episode is the
one-leg mission with no stations: :class:`MissionSpec` with ``stations=0``, the default, draws
exactly the start and goal :func:`sessgan_core.route_certificate.place_start_goal` draws.

Stations follow the rules of start and goal (module :mod:`sessgan_core.route_certificate`):

* The first station is the goal ``place_start_goal`` draws (far from the start along the
  route), so the first leg of a mission is the plain episode of the same map and seed.
* Every further station is a point with the clearance start and goal need
  (``robot_radius + clearance_margin``), drawn from the seed on its own random stream, at
  least :func:`~sessgan_core.route_certificate.min_route_steps` along the route from the
  previous station and at least half as far as the farthest such point.
* Home is the start's position; every yaw points along the route arriving there.
* Every leg is certified on its own (:func:`~sessgan_core.route_certificate.certify`): a
  mission is a valid test only when every leg is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sessgan_core.environment import MAX_STATIONS
from sessgan_core.errors import InvalidMissionError
from sessgan_core.grid_search import bfs, flat_grid, steps_of, to_cell, to_flat, unvisited
from sessgan_core.route_certificate import (
    HEADING_LOOKAHEAD_M,
    CertificateGrid,
    Placement,
    RouteCertificate,
    certify,
    map_clearance,
    min_route_steps,
    place_start_goal,
    required_clearances,
)
from sessgan_core.scenarios import Scenario
from sessgan_core.validation import require_non_negative

MAX_MISSION_STATIONS = MAX_STATIONS
"""Most stations a mission may have before home (each adds a leg and a dwell)."""

DEFAULT_DWELL_TIME = 2.0
"""Sim seconds a robot stands at each station (loading) unless told otherwise."""

STATION_SEED_KEY = 0x57A7
"""Spawn key of the stations' random stream (start and goal keep theirs)."""

Pose = tuple[float, float, float]
"""(x, y, yaw) in metres and radians, map frame."""


class MissionRejection:
    """Why a mission is not a valid test, beyond the start and goal's own reasons."""

    NO_FAR_STATION = 'no_far_station'
    """No clear point lies far enough along a route from the previous station."""
    UNCERTIFIED_LEG = 'uncertified_leg'
    """A leg has no certified route."""


@dataclass(frozen=True)
class MissionSpec:
    """What a user asks for: how many stations before home, and how long to dwell at each.

    The one place missions are validated; the generator node, the simulator's free mode and
    the campaign all build one from their parameters.
    """

    stations: int = 0
    """Stations visited before home; 0: a plain start -> goal episode (one leg)."""
    dwell_time: float = DEFAULT_DWELL_TIME
    """Sim seconds standing still at each station before the next goal goes out."""

    def validate(self) -> MissionSpec:
        """This spec, or InvalidMissionError naming what is wrong."""
        stations = self.stations
        if (not isinstance(stations, (int, np.integer)) or isinstance(stations, bool)
                or not 0 <= stations <= MAX_MISSION_STATIONS):
            raise InvalidMissionError(
                f'mission_stations must be an integer in 0..{MAX_MISSION_STATIONS} (stations '
                f'before home; 0: a plain start -> goal episode), got {stations!r}')
        dwell = self.dwell_time
        if isinstance(dwell, bool):  # a number to Python, a mistake here
            raise InvalidMissionError(f'station_dwell_time must be >= 0 s, got {dwell!r}')
        require_non_negative('station_dwell_time', dwell, InvalidMissionError, ' s')
        return self

    @property
    def legs(self) -> int:
        """Legs of the mission: one per station, plus the way home (1 without stations)."""
        return self.stations + 1


class MissionPlacement(NamedTuple):
    """Start, stations, goal (home, or the plain goal) and the legs' certificates."""

    start: Pose | None
    stations: tuple[Pose, ...]
    """Waypoints before ``goal``, in visiting order (() for a plain episode)."""
    goal: Pose | None
    """The last waypoint: home for a mission, the drawn goal for a plain episode."""
    legs: tuple[RouteCertificate, ...]
    """One certified route per leg (start -> first waypoint -> ... -> goal)."""
    placement: Placement
    """The start and goal draw the mission is built on."""
    rejection: str
    """'' for a valid test, else a Rejection or MissionRejection value."""

    @property
    def route_length(self) -> float:
        """m, the legs' certified routes together."""
        return float(sum(leg.length for leg in self.legs))

    @property
    def bottleneck_clearance(self) -> float:
        """m, the tightest passage of any leg (0 without legs)."""
        return float(min((leg.bottleneck_clearance for leg in self.legs), default=0.0))


def _arrival_yaw(grid: CertificateGrid, path: list[tuple[int, int]]) -> float:
    """Yaw of the route's last HEADING_LOOKAHEAD_M (0 for a route of one cell)."""
    lookahead = max(1, min(len(path) - 1, round(HEADING_LOOKAHEAD_M / grid.cell_size)))
    if len(path) < 2:
        return 0.0
    (x0, y0), (x1, y1) = grid.centre(path[-1 - lookahead]), grid.centre(path[-1])
    return math.atan2(y1 - y0, x1 - x0) if (x0, y0) != (x1, y1) else 0.0


def _draw_station(grid: CertificateGrid, previous: tuple[int, int], shape: tuple[int, int],
                  place_need: float, route_need: float,
                  rng: np.random.Generator) -> tuple[int, int] | None:
    """A clear certificate cell far along the route from ``previous``, or None."""
    routable = grid.clearance >= route_need - 1e-9
    flat = flat_grid(routable)
    dist = unvisited(flat)
    bfs(flat, to_flat(flat, previous), dist)
    rows, cols = np.nonzero(grid.clearance >= place_need - 1e-9)
    candidates = (rows + 1) * flat.stride + cols + 1
    steps = steps_of(dist)[candidates]
    farthest = int(steps.max()) if len(steps) else -1
    far = candidates[steps >= max(min_route_steps(shape, grid.subdivision), 0.5 * farthest)]
    if not len(far) or farthest <= 0:
        return None
    return to_cell(flat, int(far[rng.integers(len(far))]))


def place_mission(occupancy: np.ndarray, resolution: float, origin: tuple[float, float],
                  spec: Scenario, seed: int, mission: MissionSpec | None = None
                  ) -> MissionPlacement:
    """Draw a mission's start, stations and home from ``seed`` and certify every leg (the
    rules are in the module docstring). Deterministic per (map, seed, stations); with no
    stations, exactly :func:`~sessgan_core.route_certificate.place_start_goal`'s episode."""
    mission = (mission or MissionSpec()).validate()
    placement = place_start_goal(occupancy, resolution, origin, spec, seed)
    if placement.start is None or placement.goal is None or placement.certificate is None:
        return MissionPlacement(None, (), None, (), placement, placement.rejection)
    if mission.stations == 0:
        return MissionPlacement(placement.start, (), placement.goal,
                                (placement.certificate,), placement, '')
    grid = placement.certificate.grid
    place_need, route_need = required_clearances(spec)
    shape = np.asarray(occupancy).shape
    rng = np.random.default_rng(
        np.random.SeedSequence(int(seed), spawn_key=(STATION_SEED_KEY,)))
    start_cell = grid.cell_of(placement.start[0], placement.start[1])
    cells = [start_cell, grid.cell_of(placement.goal[0], placement.goal[1])]
    for _ in range(mission.stations - 1):
        station = _draw_station(grid, cells[-1], shape, place_need, route_need, rng)
        if station is None:
            return MissionPlacement(None, (), None, (), placement,
                                    MissionRejection.NO_FAR_STATION)
        cells.append(station)
    cells.append(start_cell)  # home
    legs = [placement.certificate]  # the first leg is the plain episode's route
    for leg_start, leg_goal in zip(cells[1:], cells[2:]):
        certificate = certify(grid, leg_start, leg_goal, route_need)
        if certificate is None:
            return MissionPlacement(None, (), None, (), placement,
                                    MissionRejection.UNCERTIFIED_LEG)
        legs.append(certificate)
    waypoints = [(*grid.centre(cell), _arrival_yaw(grid, leg.path))
                 for cell, leg in zip(cells[1:], legs)]
    # The first station is the plain episode's goal, yaw included.
    waypoints[0] = placement.goal
    return MissionPlacement(placement.start, tuple(waypoints[:-1]), waypoints[-1],
                            tuple(legs), placement, '')


def certify_legs(occupancy: np.ndarray, resolution: float, origin: tuple[float, float],
                 spec: Scenario, waypoints: list[tuple[float, float]]
                 ) -> list[RouteCertificate | None]:
    """The certificate of every leg between consecutive map-frame points (start first);
    None for a leg without a certified route."""
    grid = map_clearance(occupancy, resolution, origin, spec)
    route_need = required_clearances(spec)[1]
    cells = [grid.cell_of(x, y) for x, y in waypoints]
    return [certify(grid, a, b, route_need) for a, b in zip(cells, cells[1:])]
