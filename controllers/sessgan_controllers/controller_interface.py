"""Domain types shared by the robot-under-test controllers, independent of ROS.

Every controller core maps one tick's inputs to one velocity command::

    command = controller.compute_command(scan, state, goal)

* ``scan``: a planar laser scan in the robot's body frame (the scanner is taken
  to sit at the robot's centre, as ``base_scan`` does in the simulator).
* ``state``: the robot pose in the odom (= map) frame and its body-frame velocity (a
  flyer's also its altitude and climb rate: odometry's z and linear.z).
* ``goal``: the goal position in the same frame as the pose.
* ``command``: a body-frame velocity (vx, vy, wz, and a flyer's climb rate vz), like
  geometry_msgs/Twist.

Controllers that plan on the episode's map (the ``map`` topic) also offer
``set_map(grid)`` (:class:`MapAwareController`); the node and in-process runners
hand them a :class:`MapData` whenever a new map arrives, before the episode's goal.
Controllers without it never see the map.

Angles are radians, counter-clockwise positive; lengths are metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from functools import lru_cache
from typing import Any, Protocol, overload, runtime_checkable

import numpy as np

from sessgan_core.validation import require_positive


@overload
def wrap_angle(angle: float) -> float: ...
@overload
def wrap_angle(angle: np.ndarray) -> np.ndarray: ...
def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Return ``angle`` (radians; a float or an array, elementwise) wrapped to [-pi, pi): the
    project's one angle wrap."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def parameter(default: Any, help: str) -> Any:  # noqa: A002 (help mirrors argparse)
    """A config dataclass field whose ``help`` becomes the ROS parameter description."""
    return field(default=default, metadata={'help': help})


def config_help(config_type: type) -> dict[str, str]:
    """Map each field of a config dataclass to its help text."""
    return {item.name: item.metadata.get('help', '') for item in fields(config_type)}


@lru_cache(maxsize=8, typed=True)
def _beam_angles(count: int, angle_min: float, angle_increment: float) -> np.ndarray:
    """ScanData.angles, computed once per scan geometry (a controller asks several times a
    tick, every tick, for the same beams)."""
    angles = wrap_angle(angle_min + angle_increment * np.arange(count))
    angles.flags.writeable = False
    return angles


@dataclass(frozen=True)
class ScanData:
    """One planar laser scan, as sensor_msgs/LaserScan carries it.

    Readings that are NaN, infinite, below ``range_min`` or above ``range_max``
    mean "no return" and are dropped by :meth:`points`.
    """

    ranges: np.ndarray
    """Range of each beam in metres, beam i at ``angle_min + i * angle_increment``."""
    angle_min: float
    """Body-frame angle of the first beam in radians."""
    angle_increment: float
    """Angle between consecutive beams in radians."""
    range_min: float
    """Shortest valid range in metres."""
    range_max: float
    """Longest valid range in metres."""

    def angles(self) -> np.ndarray:
        """Body-frame angle of every beam in radians, wrapped to [-pi, pi) (read-only: the
        same array for every scan of the same geometry)."""
        return _beam_angles(len(self.ranges), self.angle_min, self.angle_increment)

    def valid(self) -> np.ndarray:
        """Boolean mask of beams with a usable return."""
        ranges = np.asarray(self.ranges, dtype=float)
        with np.errstate(invalid='ignore'):
            return np.isfinite(ranges) & (ranges >= self.range_min) & (ranges <= self.range_max)

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """(angles, ranges) of the valid returns, in radians and metres."""
        mask = self.valid()
        return self.angles()[mask], np.asarray(self.ranges, dtype=float)[mask]

    def field_of_view(self) -> float:
        """Angular span covered by the beams in radians (at most 2 pi)."""
        return min(2.0 * math.pi, abs(self.angle_increment) * len(self.ranges))


@dataclass(frozen=True)
class RobotState:
    """Pose in the odom/map frame and velocity in the body frame."""

    x: float
    """Position in metres."""
    y: float
    """Position in metres."""
    yaw: float
    """Heading in radians."""
    vx: float = 0.0
    """Forward velocity in m/s."""
    vy: float = 0.0
    """Leftward velocity in m/s (zero for non-holonomic robots)."""
    wz: float = 0.0
    """Yaw rate in rad/s."""
    z: float = 0.0
    """Altitude in m (a flyer's underside above the ground; 0 for ground robots)."""
    vz: float = 0.0
    """Climb rate in m/s (up positive)."""

    @property
    def speed(self) -> float:
        """Planar speed in m/s."""
        return math.hypot(self.vx, self.vy)


@dataclass(frozen=True)
class Goal:
    """A goal position in the frame of :class:`RobotState` (metres)."""

    x: float
    y: float

    def distance_from(self, state: RobotState) -> float:
        """Distance in metres from the robot's position to the goal."""
        return math.hypot(self.x - state.x, self.y - state.y)

    def in_body_frame(self, state: RobotState) -> tuple[float, float]:
        """(distance in metres, bearing in radians) of the goal seen from the robot."""
        dx, dy = self.x - state.x, self.y - state.y
        return math.hypot(dx, dy), wrap_angle(math.atan2(dy, dx) - state.yaw)


@dataclass(frozen=True)
class VelocityCommand:
    """A body-frame velocity command (the fields of geometry_msgs/Twist that matter)."""

    vx: float = 0.0
    """Forward velocity in m/s."""
    vy: float = 0.0
    """Leftward velocity in m/s."""
    wz: float = 0.0
    """Yaw rate in rad/s, counter-clockwise positive."""
    vz: float = 0.0
    """Climb rate in m/s (linear.z; only a flyer uses it)."""

    def is_finite(self) -> bool:
        return all(math.isfinite(value) for value in (self.vx, self.vy, self.wz, self.vz))

    def values(self) -> tuple[float, float, float, float]:
        """(vx, vy, wz, vz): what the simulator core's Episode.step takes."""
        return float(self.vx), float(self.vy), float(self.wz), float(self.vz)


STOP = VelocityCommand()
"""The zero command."""


@dataclass(frozen=True)
class MapData:
    """An occupancy grid as nav_msgs/OccupancyGrid carries it, without the message.

    Values: 0 free, 50 low obstacle (below a flyer's altitude), 100 wall or out of bounds,
    -1 unknown. Row 0 is the row nearest the origin (lowest y), column 0 the lowest x; cell
    (row, col) covers x in [origin_x + col * resolution, origin_x + (col + 1) * resolution),
    likewise for y. The grid is not rotated.
    """

    occupancy: np.ndarray
    """int8 array of shape (height, width)."""
    resolution: float
    """Metres per cell."""
    origin: tuple[float, float] = (0.0, 0.0)
    """Map-frame position in metres of the corner of cell (0, 0)."""

    def validate(self) -> None:
        """Raise ValueError naming what is wrong with the grid."""
        grid = np.asarray(self.occupancy)
        if grid.ndim != 2 or grid.shape[0] < 1 or grid.shape[1] < 1:
            raise ValueError(f'map occupancy must be a non-empty 2-D array, got shape '
                             f'{grid.shape}')
        require_positive('map resolution', self.resolution, unit=' m')
        if len(self.origin) != 2 or not all(math.isfinite(v) for v in self.origin):
            raise ValueError(f'map origin must be two finite numbers, got {self.origin}')

    @classmethod
    def of(cls, environment: Any) -> MapData:
        """The map of anything with ``occupancy``, ``resolution`` and ``origin`` (a
        sessgan_core Environment, say), as a controller gets it from the ``map`` topic."""
        return cls(np.asarray(environment.occupancy, dtype=np.int8),
                   float(environment.resolution),
                   (float(environment.origin[0]), float(environment.origin[1])))


def observed(observation: Any) -> tuple[ScanData, RobotState]:
    """The controller's view of a sessgan_sim Observation (``scan``, ``lidar``, ``pose``,
    ``twist``, ``altitude``, ``climb_rate``), as the controller node gets it from scan and
    odom: for running a controller in-process on the simulator core, without ROS."""
    lidar, pose, twist = observation.lidar, observation.pose, observation.twist
    scan = ScanData(np.asarray(observation.scan, dtype=float), lidar.angle_min,
                    lidar.angle_increment, lidar.range_min, lidar.range_max)
    return scan, RobotState(pose.x, pose.y, pose.yaw, twist.vx, twist.vy, twist.wz,
                            float(getattr(observation, 'altitude', 0.0)),
                            float(getattr(observation, 'climb_rate', 0.0)))


class Controller(Protocol):
    """What every controller core offers; nodes and in-process runners rely on it."""

    def compute_command(
        self, scan: ScanData, state: RobotState, goal: Goal
    ) -> VelocityCommand:
        """One control step: the command to apply until the next scan."""
        ...

    def goal_reached(self, state: RobotState, goal: Goal) -> bool:
        """Whether the robot is within the controller's goal tolerance."""
        ...

    def reset(self) -> None:
        """Forget any state kept between steps (call on a new goal or episode)."""
        ...


@runtime_checkable
class MapAwareController(Controller, Protocol):
    """A controller that plans on the episode's map: it gets every new map (a new map means a
    new episode, so it also forgets what it planned on the previous one)."""

    def set_map(self, grid: MapData) -> None:
        """Use ``grid`` from now on; raise ValueError for a grid it cannot use."""
        ...


def accepts_map(controller: Any) -> bool:
    """Whether ``controller`` wants the map (has a callable ``set_map``)."""
    return callable(getattr(controller, 'set_map', None))


class StatelessController:
    """Base of the built-in controllers: no state between steps, the goal counts as reached
    within ``config.goal_tolerance``, and a command is the one of ``decide``'s full decision."""

    config: Any

    def reset(self) -> None:
        """Nothing is kept between steps; present for the Controller protocol."""

    def goal_reached(self, state: RobotState, goal: Goal) -> bool:
        return goal.distance_from(state) <= self.config.goal_tolerance

    def compute_command(
        self, scan: ScanData, state: RobotState, goal: Goal
    ) -> VelocityCommand:
        return self.decide(scan, state, goal).command

    def decide(self, scan: ScanData, state: RobotState, goal: Goal) -> Any:
        """One step's full decision (its ``command`` field is the command)."""
        raise NotImplementedError
