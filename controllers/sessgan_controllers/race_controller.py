"""Track-following race controller for a car-like robot (follow-the-gap with a speed policy).

"The goal" below is the waypoint of a route on the map
(:mod:`~sessgan_controllers.route_guidance`, ``waypoint_distance`` ahead), or the goal
itself without a map or with ``use_map`` false: then the car takes whichever branch of a
fork looks best, often one that ends in a barrier.

One step:

1. Ranges are capped at ``look_ahead_distance`` or the scanner's range,
   whichever is shorter; a beam without a return counts as open that far.
2. Disparity extension: at every jump in range larger than
   ``disparity_threshold`` the nearer range is copied over the beams the car's
   half-width plus ``safety_margin`` would sweep at that distance, so a
   direction only looks open if the car fits through it.
3. Direction policy (the track is a closed loop and the goal is typically half
   a lap away, so the straight-line bearing to the goal often points across the
   infield): the goal itself when it is in line of sight ahead; otherwise the
   open direction maximising ``extended range - goal_bias * |angle - goal
   bearing|``. The bias only breaks near-ties between gaps (a fork); the
   farthest free direction follows the track. The car never reverses: which way
   round the loop it goes is decided by the heading it starts with.
4. Steering: pure pursuit to a point on the chosen direction at
   ``steering_distance + steering_time * speed``, curvature ``2 sin(alpha) / L``
   (a direction more than 90 degrees off asks for ``2 / steering_distance``, full lock),
   sent as a yaw rate ``w = v * curvature`` (the simulator's car turns it into a
   steering angle).
5. Speed policy, purely reactive: ``v = speed_gain * free distance straight
   ahead`` (the car's corridor), capped by ``max_speed``, by the lateral
   acceleration limit for the current curvature and floored at ``min_speed``; near
   the goal itself also by ``speed_gain * goal distance``.

**Intended weakness** (what a test generator should rediscover): no anticipatory
braking. The speed follows what is free *now* and the curvature the car already
steers, never the curvature of the route ahead: on a long straight ending in a sharp
turn the car arrives fast and, with finite braking and grip, runs wide into the
barrier, the fast-sharp-turn fault of the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sessgan_controllers.controller_interface import (
    STOP,
    Goal,
    RobotState,
    ScanData,
    VelocityCommand,
    parameter,
    wrap_angle,
)
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.route_guidance import (
    RouteGuidanceConfig,
    RouteGuidanceParameters,
    RouteGuide,
    RouteGuidedController,
    route_parameter,
)
from sessgan_core.validation import require_non_negative, require_positive


@dataclass
class RaceControllerConfig(RouteGuidanceParameters):
    """Parameters of :class:`RaceController` (each becomes a ROS parameter)."""

    half_width: float = parameter(0.6, 'Half the car width (footprint radius) in m.')
    safety_margin: float = parameter(
        0.4, 'Clearance in m added to the half-width when extending disparities.')
    field_of_view: float = parameter(
        math.radians(200.0), 'Full angle in rad ahead of the car searched for open directions.')
    look_ahead_distance: float = parameter(
        25.0, 'Ranges are capped at this distance in m (or at the scan range_max if shorter).')
    disparity_threshold: float = parameter(
        0.5, 'Range jump in m between neighbouring beams treated as an obstacle edge.')
    min_open_distance: float = parameter(
        2.0, 'Extended range in m a direction needs to count as open.')
    goal_bias: float = parameter(
        2.0, 'Metres of range traded for each radian closer to the goal bearing.')
    steering_distance: float = parameter(
        2.5, 'Pure-pursuit look-ahead at standstill in m.')
    steering_time: float = parameter(
        0.3, 'Extra pure-pursuit look-ahead in s per m/s of speed.')
    max_speed: float = parameter(10.0, 'Maximum speed in m/s.')
    min_speed: float = parameter(1.5, 'Speed in m/s the car keeps while it has an open direction.')
    speed_gain: float = parameter(
        1.0, 'Speed in m/s per m of free distance straight ahead (1/s); with a 10 m scanner '
        '1.0 allows 10 m/s.')
    max_lateral_acceleration: float = parameter(
        6.0, 'Lateral acceleration in m/s^2 the speed policy allows for the current curvature.')
    goal_tolerance: float = parameter(1.0, 'Distance in m to the goal at which the car stops.')
    waypoint_distance: float = route_parameter('waypoint_distance', 8.0)
    route_clearance: float = route_parameter('route_clearance', 0.3)
    replan_deviation: float = route_parameter('replan_deviation', 3.0)
    planning_resolution: float = route_parameter('planning_resolution', 0.5)

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first parameter out of range."""
        for name in ('half_width', 'field_of_view', 'look_ahead_distance', 'disparity_threshold',
                     'steering_distance', 'max_speed', 'speed_gain', 'max_lateral_acceleration',
                     'goal_tolerance'):
            require_positive(name, getattr(self, name), InvalidConfigError)
        for name in ('safety_margin', 'min_open_distance', 'goal_bias', 'steering_time',
                     'min_speed'):
            require_non_negative(name, getattr(self, name), InvalidConfigError)
        self.validate_route_parameters()
        if self.min_speed > self.max_speed:
            raise InvalidConfigError(
                f'min_speed {self.min_speed} must not exceed max_speed {self.max_speed}')

    def route_guidance(self) -> RouteGuidanceConfig:
        """The route guidance these parameters ask for."""
        return self.route_guidance_for(self.half_width)


@dataclass(frozen=True)
class RaceDecision:
    """What one step saw and decided (for tests and logs)."""

    direction: float | None
    """Chosen body-frame direction in rad; None when nothing ahead is open or at the goal."""
    goal_in_sight: bool
    free_ahead: float
    """Free distance in m along the car's corridor straight ahead."""
    curvature: float
    """Commanded path curvature in 1/m, positive to the left."""
    command: VelocityCommand


class RaceController(RouteGuidedController):
    """Follow-the-gap race controller; see the module docstring. Keeps only its route between
    steps."""

    def __init__(self, config: RaceControllerConfig | None = None) -> None:
        self.config = config or RaceControllerConfig()
        self.config.validate()
        self.guide = RouteGuide(self.config.route_guidance())

    def decide(self, scan: ScanData, state: RobotState, goal: Goal) -> RaceDecision:
        """Run one step and return the full decision."""
        config = self.config
        goal_distance, goal_bearing = goal.in_body_frame(state)
        if goal_distance <= config.goal_tolerance:
            return RaceDecision(None, True, 0.0, 0.0, STOP)
        waypoint = self.guide.waypoint(state, goal)
        goal_distance, goal_bearing = waypoint.target.in_body_frame(state)
        angles = scan.angles()
        ranges = np.asarray(scan.ranges, dtype=float)
        valid = scan.valid()
        # The car knows the track only as far as it sees: no return means free up to the
        # sensor's range (or the look-ahead, if shorter), never beyond.
        horizon = min(config.look_ahead_distance, scan.range_max)
        capped = np.where(valid, np.minimum(ranges, horizon), horizon)
        order = np.argsort(angles)
        angles, capped = angles[order], capped[order]
        hits = valid[order]
        free_ahead = self._free_ahead(angles[hits], capped[hits], horizon)
        extended = self._extend_disparities(angles, capped)
        ahead = np.abs(angles) <= 0.5 * config.field_of_view

        goal_beam = int(np.argmin(np.abs(wrap_angle(angles - goal_bearing))))
        goal_in_sight = bool(abs(goal_bearing) <= 0.5 * config.field_of_view
                             and extended[goal_beam] >= goal_distance)
        if goal_in_sight:
            direction = goal_bearing
        else:
            open_ahead = ahead & (extended >= config.min_open_distance)
            if not open_ahead.any():
                return RaceDecision(None, False, free_ahead, 0.0, STOP)
            score = extended - config.goal_bias * np.abs(wrap_angle(angles - goal_bearing))
            score = np.where(open_ahead, score, -np.inf)
            direction = float(angles[int(np.argmax(score))])

        speed = max(state.vx, 0.0)
        steering_look_ahead = config.steering_distance + config.steering_time * speed
        if abs(direction) <= 0.5 * math.pi:
            curvature = 2.0 * math.sin(direction) / steering_look_ahead
        else:
            # Pure pursuit's 2 sin(alpha) / L turns more gently again as the target moves
            # behind the car's side: steer as hard as for a target abeam at standstill.
            curvature = math.copysign(2.0 / config.steering_distance, direction)
        target = min(config.max_speed, config.speed_gain * free_ahead)
        if curvature != 0.0:
            target = min(target, math.sqrt(config.max_lateral_acceleration / abs(curvature)))
        if goal_in_sight and waypoint.is_goal:
            target = min(target, config.speed_gain * goal_distance)
        target = max(target, config.min_speed)
        command = VelocityCommand(vx=target, vy=0.0, wz=target * curvature)
        return RaceDecision(direction, goal_in_sight, free_ahead, curvature, command)

    def _free_ahead(self, angles: np.ndarray, ranges: np.ndarray, horizon: float) -> float:
        """Distance in m to the first return inside the car's corridor straight ahead,
        at most ``horizon``."""
        along = ranges * np.cos(angles)
        across = np.abs(ranges * np.sin(angles))
        inside = (along > 0.0) & (across <= self.config.half_width)
        if not inside.any():
            return horizon
        return float(min(along[inside].min(), horizon))

    def _extend_disparities(self, angles: np.ndarray, ranges: np.ndarray) -> np.ndarray:
        """Copy the nearer range over the beams the car would sweep past each edge."""
        config = self.config
        extended = ranges.copy()
        if len(ranges) < 2:
            return extended
        spacing = float(np.median(np.diff(angles))) if len(angles) > 1 else 1.0
        spacing = max(spacing, 1e-6)
        width = config.half_width + config.safety_margin
        edges = np.flatnonzero(np.abs(np.diff(ranges)) > config.disparity_threshold)
        for edge in edges.tolist():  # ints, not numpy scalars
            near_index = edge if ranges[edge] < ranges[edge + 1] else edge + 1
            near = ranges[near_index]
            half_angle = math.asin(min(1.0, width / max(near, 1e-6)))
            reach = int(math.ceil(half_angle / spacing))
            if near_index == edge:  # nearer on the low-angle side: extend towards higher angles
                span = slice(edge + 1, min(len(ranges), edge + 1 + reach))
            else:
                span = slice(max(0, edge + 1 - reach), edge + 1)
            extended[span] = np.minimum(extended[span], near)
        return extended

