"""Local controllers that follow a :class:`~sessgan_controllers.path_planning.Path`.

The pieces, each as Nav2 has it:

* :class:`PathTracker`: the robot's progress along the path (the nearest point in a
  window ahead of the last one, so a path that doubles back is not skipped) and the
  carrot ``lookahead`` metres further on.
* :func:`speed_profile`: the speed allowed at each point of the path: ``sqrt(lateral
  acceleration / |curvature|)``, then a backward pass so that braking at
  ``deceleration`` from any point reaches every later limit in time (``v_i <= sqrt(v_j^2
  + 2 * deceleration * (s_j - s_i))``, the braking distance ``v^2 / (2 deceleration)``
  to the next sharp turn), ending at ``end_speed`` at the goal.
* :func:`free_distance`: how far along the path the robot can go before its footprint
  meets one of the given points (what the scan sees that the map does not have), for a
  speed limit that stops in time (:func:`braking_speed`: ``sqrt(2 * deceleration *
  (free distance - stop margin))`` for an obstacle that stands still and a robot that
  reacts at once, less when it may move or the robot lags).
* :func:`proximity_factor`: Nav2's cost-regulated scaling: speed times the distance from
  the footprint to the nearest return ahead over ``slowdown_distance``.
* The followers turn a carrot and a target speed into a command:
  :func:`follow_diff_drive` (rotation shim, then regulated pure pursuit),
  :func:`follow_car` (pure pursuit for a bicycle: ``wz = v * curvature`` with the
  curvature limited by the steering lock), :func:`follow_holonomic` (vx, vy towards the
  carrot, yaw turned towards the motion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sessgan_controllers.controller_interface import (
    RobotState,
    ScanData,
    VelocityCommand,
    wrap_angle,
)
from sessgan_controllers.path_planning import Path


class PathTracker:
    """Progress of the robot along one path."""

    def __init__(self, path: Path, search_distance: float) -> None:
        self.path = path
        self.search_distance = search_distance
        """The nearest point is looked for at most this far (m of arc) beyond the last one."""
        self.index = 0

    def update(self, x: float, y: float) -> float:
        """Move to the nearest point within the search window; return the distance (m) from
        (x, y) to it."""
        path = self.path
        arc = path.arc_length
        end = int(np.searchsorted(arc, arc[self.index] + self.search_distance, side='right'))
        window = path.points[self.index:max(end, self.index + 1)]
        distance = np.hypot(window[:, 0] - x, window[:, 1] - y)
        nearest = int(np.argmin(distance))
        self.index += nearest
        return float(distance[nearest])

    @property
    def travelled(self) -> float:
        """Arc length (m) of the path up to the robot's nearest point."""
        return float(self.path.arc_length[self.index])

    @property
    def remaining(self) -> float:
        """Arc length (m) from the nearest point to the path's end."""
        return self.path.length - self.travelled

    def carrot(self, lookahead: float) -> np.ndarray:
        """The path point ``lookahead`` metres of arc beyond the nearest one."""
        return self.path.point_at(self.travelled + lookahead)


def speed_profile(path: Path, max_speed: float, lateral_acceleration: float,
                  deceleration: float, end_speed: float,
                  max_curvature_speed: float = math.inf) -> np.ndarray:
    """Speed limit in m/s at each point of ``path``; see the module docstring.

    ``max_curvature_speed`` caps the speed where the path turns at all as ``value /
    |curvature|`` (a yaw-rate limit in rad/s).
    """
    curvature = np.abs(path.curvature)
    with np.errstate(divide='ignore'):
        limit = np.where(curvature > 1e-9,
                         np.minimum(np.sqrt(lateral_acceleration / np.maximum(curvature, 1e-9)),
                                    max_curvature_speed / np.maximum(curvature, 1e-9)),
                         np.inf)
    limit = np.minimum(limit, max_speed)
    limit[-1] = min(limit[-1], end_speed)
    steps = np.diff(path.arc_length)
    # Backward pass: v_i^2 <= v_{i+1}^2 + 2 a ds (plain Python: a few hundred points).
    values = limit.tolist()
    two_a = 2.0 * deceleration
    for index in range(len(values) - 2, -1, -1):
        reachable = math.sqrt(values[index + 1] ** 2 + two_a * float(steps[index]))
        if reachable < values[index]:
            values[index] = reachable
    return np.asarray(values)


def free_distance(path: Path, start_index: int, horizon: float, points: np.ndarray,
                  radius: float) -> float:
    """Arc length (m) from ``start_index`` to the first path point closer than ``radius`` to
    any of ``points`` (N x 2), looking at most ``horizon`` metres ahead; ``inf`` when none."""
    if not len(points):
        return math.inf
    arc = path.arc_length
    end = int(np.searchsorted(arc, arc[start_index] + horizon, side='right'))
    ahead = path.points[start_index:max(end, start_index + 1)]
    # Only points near the stretch can matter.
    low, high = ahead.min(axis=0) - radius, ahead.max(axis=0) + radius
    near = points[np.all((points >= low) & (points <= high), axis=1)]
    if not len(near):
        return math.inf
    gaps = np.hypot(ahead[:, None, 0] - near[None, :, 0], ahead[:, None, 1] - near[None, :, 1])
    blocked = np.flatnonzero(gaps.min(axis=1) < radius)
    if not len(blocked):
        return math.inf
    return float(arc[start_index + int(blocked[0])] - arc[start_index])


PROXIMITY_HALF_ANGLE = math.radians(35.0)
"""Returns within this angle of the direction of travel regulate the speed; walls beside a
corridor (at 90 degrees) do not."""


def proximity_factor(scan: ScanData, robot_radius: float, direction: float,
                     slowdown_distance: float, min_factor: float) -> float:
    """Speed factor in [min_factor, 1] from the distance between the footprint and the nearest
    return within :data:`PROXIMITY_HALF_ANGLE` of ``direction`` (body frame, rad)."""
    if slowdown_distance <= 0.0:
        return 1.0
    angles, ranges = scan.points()
    ahead = np.cos(angles - direction) > math.cos(PROXIMITY_HALF_ANGLE)
    if not ahead.any():
        return 1.0
    gap = float(ranges[ahead].min()) - robot_radius
    return min(1.0, max(min_factor, gap / slowdown_distance))


def nearest_gap_ahead(points: np.ndarray, state: RobotState, direction: float,
                      robot_radius: float) -> float:
    """Gap (m) between the footprint and the nearest of map-frame ``points`` (N x 2) in the
    half-plane ahead of body-frame ``direction`` (rad); inf when there is none."""
    if not len(points):
        return math.inf
    dx, dy = points[:, 0] - state.x, points[:, 1] - state.y
    heading = state.yaw + direction
    ahead = dx * math.cos(heading) + dy * math.sin(heading) > 0.0
    if not ahead.any():
        return math.inf
    return float(np.hypot(dx[ahead], dy[ahead]).min()) - robot_radius


def swept_points(state: RobotState, command: VelocityCommand, length: float,
                 step: float) -> np.ndarray:
    """Map-frame positions (N x 2) the robot's centre passes in the first ``length`` metres of
    ``command`` held constant: an arc of curvature wz / vx for a forward command without vy,
    else the straight line along (vx, vy) (a holonomic robot's yaw does not bend its motion
    much over a short check)."""
    count = max(2, int(math.ceil(length / step)) + 1)
    distance = np.linspace(0.0, length, count)
    speed = math.hypot(command.vx, command.vy)
    if command.vy == 0.0 and command.vx > 1e-9 and abs(command.wz) > 1e-9:
        curvature = command.wz / command.vx
        x = np.sin(curvature * distance) / curvature
        y = (1.0 - np.cos(curvature * distance)) / curvature
    elif speed > 1e-9:
        x = distance * command.vx / speed
        y = distance * command.vy / speed
    else:
        x = y = np.zeros(count)
    cos_yaw, sin_yaw = math.cos(state.yaw), math.sin(state.yaw)
    return np.stack((state.x + cos_yaw * x - sin_yaw * y, state.y + sin_yaw * x + cos_yaw * y),
                    axis=1)


def braking_speed(distance: float, deceleration: float, margin: float,
                  reaction_time: float = 0.0, obstacle_speed: float = 0.0) -> float:
    """Fastest speed v (m/s) that still stops ``margin`` short of something ``distance``
    metres ahead: the robot keeps v for ``reaction_time`` s, then brakes at ``deceleration``,
    while the obstacle closes in at ``obstacle_speed``::

        v t_r + v^2 / (2 a) + u (t_r + v / a) <= distance - margin
    """
    room = distance - margin - obstacle_speed * reaction_time
    if not room > 0.0:
        return 0.0
    if math.isinf(room):
        return math.inf
    linear = reaction_time + obstacle_speed / deceleration
    return deceleration * (-linear + math.sqrt(linear * linear + 2.0 * room / deceleration))


def to_body(state: RobotState, point: np.ndarray) -> tuple[float, float]:
    """Map-frame ``point`` in the robot's body frame (m)."""
    dx, dy = float(point[0]) - state.x, float(point[1]) - state.y
    cos_yaw, sin_yaw = math.cos(state.yaw), math.sin(state.yaw)
    return cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy


# ------------------------------------------------------------------------------------------
# Followers


@dataclass(frozen=True)
class DiffDriveLimits:
    max_angular_speed: float
    """rad/s"""
    angular_deceleration: float
    """rad/s^2 used to stop a turn in place on the heading."""
    lateral_acceleration: float
    """m/s^2: the speed on the carrot's arc is at most sqrt(this / curvature)."""
    rotate_speed: float
    """rad/s of a turn in place."""
    rotate_start_angle: float
    """rad of heading error to the carrot above which the robot turns in place."""
    rotate_stop_angle: float
    """rad of heading error below which a turn in place ends."""


def follow_diff_drive(state: RobotState, carrot: np.ndarray, speed: float,
                      limits: DiffDriveLimits, rotating: bool) -> tuple[VelocityCommand, bool]:
    """(command, still turning in place) towards ``carrot`` at most at ``speed`` m/s.

    Rotation shim: with the carrot more than ``rotate_start_angle`` off the heading, turn in
    place (yaw rate limited so that it can stop on the heading at ``angular_deceleration``)
    until it is within ``rotate_stop_angle``. Otherwise regulated pure pursuit: curvature
    ``2 y / L^2`` of the arc through the carrot (body frame (x, y), L its distance), speed
    limited on that arc by the lateral acceleration and the yaw-rate limit.
    """
    x, y = to_body(state, carrot)
    error = math.atan2(y, x)
    if rotating or abs(error) > limits.rotate_start_angle:
        if abs(error) > limits.rotate_stop_angle:
            rate = min(limits.rotate_speed,
                       math.sqrt(2.0 * limits.angular_deceleration * abs(error)))
            return VelocityCommand(0.0, 0.0, math.copysign(rate, error)), True
    distance_sq = x * x + y * y
    if distance_sq < 1e-12:
        return VelocityCommand(), False
    curvature = 2.0 * y / distance_sq
    if abs(curvature) > 1e-9:
        speed = min(speed, math.sqrt(limits.lateral_acceleration / abs(curvature)),
                    limits.max_angular_speed / abs(curvature))
    return VelocityCommand(speed, 0.0, speed * curvature), False


@dataclass(frozen=True)
class CarLimits:
    wheelbase: float
    """m between the axles; the body's centre lies halfway."""
    max_steering_angle: float
    """rad"""
    lateral_acceleration: float
    """m/s^2 allowed on the commanded arc."""


def follow_car(state: RobotState, carrot: np.ndarray, speed: float,
               limits: CarLimits) -> VelocityCommand:
    """Pure pursuit for a kinematic bicycle towards ``carrot`` at most at ``speed`` m/s.

    The arc is taken from the rear axle (half a wheelbase behind the centre), curvature
    ``2 sin(alpha) / L``, limited by the steering lock to ``tan(max_steering) / wheelbase``;
    the command is ``wz = v * curvature`` (the simulator's car turns it back into a
    steering angle), with ``v`` at most ``sqrt(lateral acceleration / |curvature|)``.
    """
    x, y = to_body(state, carrot)
    x += 0.5 * limits.wheelbase  # from the rear axle
    distance = math.hypot(x, y)
    if distance < 1e-6:
        return VelocityCommand()
    alpha = math.atan2(y, x)
    curvature = 2.0 * math.sin(alpha) / distance
    if abs(alpha) > 0.5 * math.pi:  # carrot behind: full lock towards it
        curvature = math.copysign(math.inf, alpha)
    max_curvature = math.tan(limits.max_steering_angle) / limits.wheelbase
    curvature = max(-max_curvature, min(max_curvature, curvature))
    if abs(curvature) > 1e-9:
        speed = min(speed, math.sqrt(limits.lateral_acceleration / abs(curvature)))
    return VelocityCommand(speed, 0.0, speed * curvature)


@dataclass(frozen=True)
class HolonomicLimits:
    yaw_gain: float
    """rad/s of yaw rate per rad of heading error towards the motion."""
    max_yaw_rate: float
    """rad/s"""


def follow_holonomic(state: RobotState, carrot: np.ndarray, speed: float,
                     limits: HolonomicLimits) -> VelocityCommand:
    """Velocity ``speed`` (m/s) straight towards ``carrot`` in the body frame (vx, vy), yaw
    turned towards the direction of motion."""
    x, y = to_body(state, carrot)
    distance = math.hypot(x, y)
    if distance < 1e-6:
        return VelocityCommand()
    direction = math.atan2(y, x)
    rate = limits.yaw_gain * wrap_angle(direction)
    rate = max(-limits.max_yaw_rate, min(limits.max_yaw_rate, rate))
    return VelocityCommand(speed * x / distance, speed * y / distance, rate)
