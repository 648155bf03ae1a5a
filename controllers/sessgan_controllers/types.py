"""Domain types shared by the robot-under-test controllers, independent of ROS.

Every controller core maps one tick's inputs to one velocity command::

    command = controller.compute_command(scan, state, goal)

* ``scan``: a planar laser scan in the robot's body frame (the scanner is taken
  to sit at the robot's centre, as ``base_scan`` does in the simulator).
* ``state``: the robot pose in the odom (= map) frame and its body-frame velocity.
* ``goal``: the goal position in the same frame as the pose.
* ``command``: a body-frame velocity (vx, vy, wz), like geometry_msgs/Twist.

Angles are radians, counter-clockwise positive; lengths are metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np


def wrap_angle(angle: float) -> float:
    """Return ``angle`` (radians) wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def parameter(default: Any, help: str) -> Any:  # noqa: A002 (help mirrors argparse)
    """A config dataclass field whose ``help`` becomes the ROS parameter description."""
    return field(default=default, metadata={'help': help})


def config_help(config_type: type) -> dict[str, str]:
    """Map each field of a config dataclass to its help text."""
    return {item.name: item.metadata.get('help', '') for item in fields(config_type)}


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
        """Body-frame angle of every beam in radians, wrapped to [-pi, pi)."""
        raw = self.angle_min + self.angle_increment * np.arange(len(self.ranges))
        return (raw + math.pi) % (2.0 * math.pi) - math.pi

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

    def is_finite(self) -> bool:
        return all(math.isfinite(value) for value in (self.vx, self.vy, self.wz))


STOP = VelocityCommand()
"""The zero command."""


def observed(observation: Any) -> tuple[ScanData, RobotState]:
    """The controller's view of a sessgan_sim Observation (``scan``, ``lidar``, ``pose``,
    ``twist``), as the controller node gets it from scan and odom: for running a controller
    in-process on the simulator core, without ROS."""
    lidar, pose, twist = observation.lidar, observation.pose, observation.twist
    scan = ScanData(np.asarray(observation.scan, dtype=float), lidar.angle_min,
                    lidar.angle_increment, lidar.range_min, lidar.range_max)
    return scan, RobotState(pose.x, pose.y, pose.yaw, twist.vx, twist.vy, twist.wz)


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
