"""Sensors of the robot under test: a planar lidar, odometry, contact and clearance.

The lidar casts all its beams in one ``p.rayTestBatch`` call, in the robot's body
frame, from the body's centre at the robot's sensor height (frame ``base_scan``
sits on ``base_footprint``'s z axis). What it sees follows from that height:

* ground robots (scan plane 0.2 m) see walls, out-of-bounds barriers, low
  obstacles (0.3 m) and ground agents;
* the flyer (scan plane at its cruise altitude, 1.0 m) sees walls and other
  flyers, but not low obstacles: they lie below its scan plane, as they would
  for a real planar lidar on a drone. They remain on the ``map`` topic (value 50)
  for controllers that must consider them.

Readings follow REP 117: a beam with no return within ``range_max`` reads +inf,
a return closer than ``range_min`` reads -inf; other returns get Gaussian noise
of ``noise_std`` metres, drawn from the episode's seeded generator, and are kept
within [range_min, range_max].
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pybullet as p

from sessgan_gen.environment import Pose2D
from sessgan_sim.errors import InvalidConfigError, SessganSimError
from sessgan_sim.robots import Robot
from sessgan_sim.world import SCAN_RAY_MASK, WorldLayout

_HIT_FRACTION = operator.itemgetter(2)

CONTACT_TOLERANCE = 1e-3
"""m: contact points closer than this (or penetrating) count as touching."""


@dataclass(frozen=True)
class LidarConfig:
    """A planar laser scanner. Angles in radians, lengths in metres."""

    beams: int = 360
    field_of_view: float = 2 * math.pi
    """Centred on the robot's heading; 2*pi is a full turn."""
    range_min: float = 0.12
    range_max: float = 10.0
    rate_hz: float = 20.0
    """Scans per sim second; a scan is taken at the first control tick it is due."""
    noise_std: float = 0.01
    """Standard deviation of the Gaussian range noise; 0 gives exact ranges."""

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable parameter."""
        if not (isinstance(self.beams, int) and 1 <= self.beams <= 16384):
            raise InvalidConfigError(f'lidar: beams must be an integer in 1..16384, '
                                     f'got {self.beams!r}')
        if not (math.isfinite(self.field_of_view) and 0 < self.field_of_view <= 2 * math.pi):
            raise InvalidConfigError(f'lidar: field_of_view must be in (0, 2*pi] rad, got '
                                     f'{self.field_of_view}')
        if not (math.isfinite(self.range_min) and self.range_min >= 0):
            raise InvalidConfigError(f'lidar: range_min must be >= 0 m, got {self.range_min}')
        if not (math.isfinite(self.range_max) and self.range_max > self.range_min):
            raise InvalidConfigError(f'lidar: range_max must exceed range_min, got '
                                     f'{self.range_max} <= {self.range_min}')
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise InvalidConfigError(f'lidar: rate_hz must be > 0, got {self.rate_hz}')
        if not (math.isfinite(self.noise_std) and self.noise_std >= 0):
            raise InvalidConfigError(f'lidar: noise_std must be >= 0 m, got {self.noise_std}')

    @property
    def info(self) -> LidarInfo:
        """The scan's geometry as sensor_msgs/LaserScan states it."""
        full_turn = math.isclose(self.field_of_view, 2 * math.pi)
        if self.beams == 1:
            increment = 0.0
        elif full_turn:
            # The last beam must not repeat the first one.
            increment = self.field_of_view / self.beams
        else:
            increment = self.field_of_view / (self.beams - 1)
        angle_min = -self.field_of_view / 2 if self.beams > 1 else 0.0
        return LidarInfo(
            beams=self.beams, angle_min=angle_min,
            angle_max=angle_min + increment * (self.beams - 1), angle_increment=increment,
            range_min=self.range_min, range_max=self.range_max, scan_time=1.0 / self.rate_hz)


@dataclass(frozen=True)
class LidarInfo:
    """Geometry of a scan: beam i points at ``angle_min + i * angle_increment`` (body frame)."""

    beams: int
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    scan_time: float
    """Seconds between scans; all beams of a scan are taken at once (time_increment 0)."""

    def angles(self) -> np.ndarray:
        """Body-frame angle of every beam in radians."""
        return self.angle_min + self.angle_increment * np.arange(self.beams)


class Lidar:
    """Casts the beams of one scan against the world; one instance per episode."""

    def __init__(self, config: LidarConfig, rng: np.random.Generator) -> None:
        config.validate()
        self.config = config
        self.info = config.info
        self._rng = rng
        self._client = -1
        self._body = -1
        self._starts: list[list[float]] = []
        self._ends: list[list[float]] = []

    def attach(self, client: int, robot: Robot) -> None:
        """Mount the lidar on ``robot`` (already spawned): beams start at its centre at its
        sensor height and are cast in its body frame."""
        angles = self.info.angles()
        offset = robot.sensor_height - robot.ride_height
        starts = np.zeros((self.info.beams, 3))
        starts[:, 2] = offset
        ends = np.stack([np.cos(angles) * self.config.range_max,
                         np.sin(angles) * self.config.range_max,
                         np.full(self.info.beams, offset)], axis=1)
        self._starts, self._ends = starts.tolist(), ends.tolist()
        self._client = client
        self._body = robot.body_id

    def scan(self) -> np.ndarray:
        """Ranges of one scan in metres (float32, a new read-only array)."""
        if self._body < 0:
            raise SessganSimError('lidar: attach() it to a spawned robot before scanning')
        hits = p.rayTestBatch(self._starts, self._ends, numThreads=1,
                              parentObjectUniqueId=self._body,
                              collisionFilterMask=SCAN_RAY_MASK, physicsClientId=self._client)
        fractions = np.fromiter(map(_HIT_FRACTION, hits), dtype=np.float64,
                                count=self.info.beams)
        config = self.config
        ranges = fractions * config.range_max
        missed = fractions >= 1.0
        too_close = ranges < config.range_min
        if config.noise_std > 0:
            ranges += self._rng.normal(0.0, config.noise_std, self.info.beams)
            np.clip(ranges, config.range_min, config.range_max, out=ranges)
        ranges[missed] = math.inf
        ranges[too_close] = -math.inf
        result = ranges.astype(np.float32)
        result.flags.writeable = False
        return result


class Twist2D(NamedTuple):
    """Body-frame velocity: m/s and rad/s."""

    vx: float
    vy: float
    wz: float


class Odometry(NamedTuple):
    """Pose in the odom (= map) frame and body-frame twist; localisation is perfect."""

    pose: Pose2D
    twist: Twist2D


def read_odometry(robot: Robot) -> Odometry:
    """The robot's odometry after the last physics step."""
    state = robot.state
    return Odometry(Pose2D(state.x, state.y, state.yaw), Twist2D(state.vx, state.vy, state.wz))


def in_contact(client: int, body_id: int, tolerance: float = CONTACT_TOLERANCE) -> bool:
    """Whether ``body_id`` touches anything it collides with (its contact points from the last
    physics step, penetrating or closer than ``tolerance`` metres)."""
    for point in p.getContactPoints(bodyA=body_id, physicsClientId=client):
        if point[8] <= tolerance:
            return True
    return False


class ClearanceSensor:
    """Distance from the robot's body to the nearest obstacle or agent, up to a range.

    Uses ``p.getClosestPoints`` with ``range`` as the threshold, only against the bodies
    whose bounding box lies within reach (a numpy pre-filter), so a tick costs a few
    pair queries whatever the map's size.
    """

    def __init__(self, client: int, robot: Robot, layout: WorldLayout, range_: float) -> None:
        if not (math.isfinite(range_) and range_ > 0):
            raise InvalidConfigError(f'clearance range must be > 0 m, got {range_}')
        self.range = range_
        self._client = client
        self._robot = robot
        self._layout = layout
        self._reach = robot.footprint_radius + range_

    def measure(self, agent_ids: list[int], agent_positions: np.ndarray,
                agent_radius: float) -> float:
        """Clearance in metres: 0 when touching, ``range`` when nothing is within range."""
        x, y = self._robot.position
        candidates = self._layout.obstacles_near(x, y, self._reach)
        if agent_ids:
            gaps = np.hypot(agent_positions[:, 0] - x, agent_positions[:, 1] - y)
            near = np.flatnonzero(gaps <= self._reach + agent_radius)
            candidates += [agent_ids[index] for index in near.tolist()]
        clearance = self.range
        body, client, range_ = self._robot.body_id, self._client, self.range
        for other in candidates:
            for point in p.getClosestPoints(body, other, range_, physicsClientId=client):
                if point[8] < clearance:
                    clearance = point[8]
        return max(clearance, 0.0)
