"""The Environment: one test map with a start and a goal (or a mission), independent of ROS.

Grids are stored in nav_msgs/OccupancyGrid order: ``occupancy[row, col]`` with
row 0 at the map origin (lowest y) and col 0 at the lowest x. Cell (row, col)
covers x in [origin_x + col*res, origin_x + (col+1)*res), likewise for y.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np

from sessgan_core.errors import InvalidEnvironmentError
from sessgan_core.scenarios import OCCUPANCY_VALUES, get_scenario
from sessgan_core.validation import require_non_negative, require_positive

MAX_CELLS_PER_SIDE = 4096
"""Grids larger than this per side are rejected as absurd (memory and build time)."""

MAX_TOTAL_CELLS = 1024 * 1024
"""Grids of more cells than this (1,048,576) are rejected: the simulator's time and memory
grow with the cells. Measured on a 2-core host, a 1024 x 1024 map with 10 % walls took 22 s
and 1.3 GB to build and 5.6 wall s per sim second (a 4096 x 4096 map, which the old limit
allowed, took 262 s and 3.3 GB to build); generating a 1024 x 1024 map took 6.4 s and
0.7 GB."""

MAX_STATIONS = 16
"""Most mission stations an Environment may hold (sessgan_core.missions.MAX_MISSION_STATIONS)."""

MAX_ROBOTS = 8
"""Most robots under test in one fleet episode (each adds a controller and its topics)."""

MAX_ENVIRONMENT_ID_LENGTH = 128
ENVIRONMENT_ID_PATTERN = re.compile(r'[A-Za-z0-9][A-Za-z0-9._-]{0,127}')
"""Environment ids name failure bag directories and files, so they are safe file names: a
letter or digit, then up to 127 letters, digits, '.', '_' or '-'; never '..' (no path
escapes) and never '.tmp-' (the staging name of a bag being written)."""


def check_environment_id(environment_id: object) -> str:
    """``environment_id`` if it is a safe id (:data:`ENVIRONMENT_ID_PATTERN`), else
    InvalidEnvironmentError saying why."""
    if not isinstance(environment_id, str):
        raise InvalidEnvironmentError(
            f'environment id must be a string, got {type(environment_id).__name__}')
    if not environment_id:
        raise InvalidEnvironmentError('environment id is empty')
    if len(environment_id) > MAX_ENVIRONMENT_ID_LENGTH:
        raise InvalidEnvironmentError(
            f'environment id {environment_id[:40]!r}... has {len(environment_id)} characters; '
            f'at most {MAX_ENVIRONMENT_ID_LENGTH}')
    if (not ENVIRONMENT_ID_PATTERN.fullmatch(environment_id) or '..' in environment_id
            or '.tmp-' in environment_id):
        raise InvalidEnvironmentError(
            f'environment id {environment_id!r} is not a safe name: it must start with a '
            'letter or digit and hold only letters, digits, ".", "_" and "-" (no "..", no '
            '".tmp-"), because it names the failure bag directory')
    return environment_id


def check_grid_size(width: int, height: int) -> None:
    """InvalidEnvironmentError unless a ``width`` x ``height`` grid is within
    :data:`MAX_CELLS_PER_SIDE` per side and :data:`MAX_TOTAL_CELLS` in all."""
    if not (1 <= height <= MAX_CELLS_PER_SIDE and 1 <= width <= MAX_CELLS_PER_SIDE):
        raise InvalidEnvironmentError(
            f'grid {width}x{height} cells is outside 1..{MAX_CELLS_PER_SIDE} per side')
    if width * height > MAX_TOTAL_CELLS:
        raise InvalidEnvironmentError(
            f'grid {width}x{height} has {width * height:,} cells, more than the '
            f'{MAX_TOTAL_CELLS:,} a simulator accepts (MAX_TOTAL_CELLS)')


@dataclass(frozen=True)
class Pose2D:
    """A planar pose in the map frame: metres and radians."""

    x: float
    y: float
    yaw: float = 0.0


@dataclass(frozen=True)
class FleetRobot:
    """The start and goal of one more robot under test in a fleet episode (robot ``r1``,
    ``r2``, ...; robot ``r0`` drives the environment's own start and goal)."""

    start: Pose2D
    goal: Pose2D
    route_length: float = 0.0
    """m, length of its certified route (0 when not known)."""


@dataclass
class Environment:
    """One environment to evaluate; the core twin of sessgan_interfaces/Environment."""

    id: str
    scenario: str
    occupancy: np.ndarray
    """int8 array (height, width) of OccupancyGrid values 0 / 50 / 100."""
    resolution: float
    """Metres per cell."""
    start: Pose2D
    goal: Pose2D
    origin: tuple[float, float] = (0.0, 0.0)
    """Map-frame position (x, y) of the outer corner of cell (0, 0)."""
    seed: int = 0
    generation: int = -1
    member: int = -1
    feasible: bool = True
    """A valid test: start and goal joined by a certified route
    (sessgan_core.route_certificate)."""
    route_length: float = 0.0
    """m, length of the certified route (0 when not a valid test or not known)."""
    route_min_clearance: float = 0.0
    """m, bottleneck clearance of the route: the tightest passage between start and goal."""
    extra: dict = field(default_factory=dict)
    stations: tuple[Pose2D, ...] = ()
    """Mission stations (pick-up, place, ...) visited in order before ``goal``, which is then
    home; () for a plain start -> goal episode (sessgan_core.missions)."""
    dwell_time: float = 0.0
    """Sim seconds the robot stands still at each station before its next goal goes out."""
    fleet: tuple[FleetRobot, ...] = ()
    """More robots under test in the same world, each with its own start and goal (a fleet
    episode); () for one robot under test (sessgan_core.fleet)."""

    def moved_to(self, origin: tuple[float, float]) -> Environment:
        """This environment with its map at ``origin``: every pose moves with the map (the
        same test in another map frame, e.g. a facility generator's training map's)."""
        dx, dy = float(origin[0]) - self.origin[0], float(origin[1]) - self.origin[1]
        if dx == 0.0 and dy == 0.0:
            return self

        def moved(pose: Pose2D) -> Pose2D:
            return Pose2D(pose.x + dx, pose.y + dy, pose.yaw)

        return replace(
            self, origin=(float(origin[0]), float(origin[1])), start=moved(self.start),
            goal=moved(self.goal), stations=tuple(moved(pose) for pose in self.stations),
            fleet=tuple(replace(robot, start=moved(robot.start), goal=moved(robot.goal))
                        for robot in self.fleet))

    @property
    def waypoints(self) -> tuple[Pose2D, ...]:
        """Every goal of the episode in order: the stations, then ``goal``."""
        return (*self.stations, self.goal)

    @property
    def legs(self) -> int:
        """Legs of the episode's mission (1 for a plain start -> goal episode)."""
        return len(self.stations) + 1

    @property
    def robots(self) -> int:
        """Robots under test: 1 plus the fleet's."""
        return 1 + len(self.fleet)

    @property
    def height(self) -> int:
        return int(self.occupancy.shape[0])

    @property
    def width(self) -> int:
        return int(self.occupancy.shape[1])

    def cell_center(self, row: int, col: int) -> tuple[float, float]:
        """Map-frame centre (x, y) in metres of cell (row, col)."""
        return (self.origin[0] + (col + 0.5) * self.resolution,
                self.origin[1] + (row + 0.5) * self.resolution)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """Cell (row, col) containing map-frame point (x, y); may be outside the grid."""
        return (int(math.floor((y - self.origin[1]) / self.resolution)),
                int(math.floor((x - self.origin[0]) / self.resolution)))

    def validate(self) -> None:
        """Raise InvalidEnvironmentError naming the first thing that is wrong."""
        check_environment_id(self.id)
        get_scenario(self.scenario)  # raises UnknownScenarioError
        grid = self.occupancy
        if not isinstance(grid, np.ndarray) or grid.ndim != 2:
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: occupancy must be a 2-D array, '
                f'got shape {getattr(grid, "shape", None)}')
        height, width = grid.shape
        try:
            check_grid_size(width, height)
        except InvalidEnvironmentError as err:
            raise InvalidEnvironmentError(f'environment {self.id!r}: {err}') from err
        require_positive(f'environment {self.id!r}: resolution', self.resolution,
                         InvalidEnvironmentError, ' m per cell')
        if not all(math.isfinite(v) for v in self.origin):
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: origin {self.origin} is not finite')
        bad = ~np.isin(grid, OCCUPANCY_VALUES)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: cell ({row}, {col}) has occupancy {grid[row, col]}; '
                f'expected one of {OCCUPANCY_VALUES}')
        if len(self.stations) > MAX_STATIONS:
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: {len(self.stations)} mission stations; at most '
                f'{MAX_STATIONS}')
        require_non_negative(f'environment {self.id!r}: dwell time', self.dwell_time,
                             InvalidEnvironmentError, ' s')
        if len(self.fleet) + 1 > MAX_ROBOTS:
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: {len(self.fleet) + 1} robots under test; at most '
                f'{MAX_ROBOTS}')
        if self.fleet and self.stations:
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: a fleet episode has no mission stations (each '
                f'robot drives start -> goal)')
        stations = [(f'station {index + 1}', pose) for index, pose in enumerate(self.stations)]
        fleet = [(f'robot r{index + 1} {end}', pose)
                 for index, robot in enumerate(self.fleet)
                 for end, pose in (('start', robot.start), ('goal', robot.goal))]
        for label, pose in (('start', self.start), ('goal', self.goal), *stations, *fleet):
            if not all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw)):
                raise InvalidEnvironmentError(
                    f'environment {self.id!r}: {label} {pose} is not finite')
            row, col = self.cell_of(pose.x, pose.y)
            if not (0 <= row < height and 0 <= col < width):
                raise InvalidEnvironmentError(
                    f'environment {self.id!r}: {label} ({pose.x:.2f}, {pose.y:.2f}) m lies '
                    f'outside '
                    f'the {width}x{height} grid')
