"""Velocity-projection obstacle avoidance for a holonomic flyer.

The avoidance method of the paper's drone (its Fig. 2): the flyer heads for the
goal, projects its motion direction forward and checks the scan only inside a
narrow field of view around that direction, up to a speed-dependent look-ahead.
"The goal" below is the waypoint of a route on the map
(:mod:`~sessgan_controllers.route_guidance`), or the goal itself without a map or with
``use_map`` false.

One step:

1. The reference direction is the current velocity direction (the goal
   bearing while the flyer is nearly at rest).
2. Candidate motion directions: the goal bearing and a ring of directions,
   limited to within half the field of view of the reference direction while
   moving (a flyer can only steer into what it looks at); every direction
   when nearly at rest.
3. A candidate is blocked when a scan point inside the field of view *around
   that candidate* lies in the corridor the flyer sweeps along it (half-width
   ``robot_radius + safety_margin``) within the look-ahead
   ``look_ahead_distance + look_ahead_time * speed`` (towards the goal: up to
   the goal, with the margin capped at half the goal's clearance).
4. The free candidate closest to the goal bearing wins; speed is the arrival
   speed towards the goal, limited by the distance to the nearest point in view.
   With no free candidate the flyer brakes to a hover and, once at rest, looks
   around for a new direction. It also brakes when the route turns out of view (a
   waypoint more than half the field of view off its motion): it stops to look that way.

**Altitude** (:mod:`~sessgan_controllers.altitude_control`): the flyer starts landed. It
first climbs in place to ``cruise_altitude`` (the other flyers' flight level) and moves
sideways only above ``takeoff_altitude``, over the low obstacles; from there on the route
treats low obstacles as free space (they lie below it, and below its scan plane) and every
command holds the cruise altitude.

**Intended weakness** (what a test generator should rediscover): the narrow field of
view. Points outside it are ignored by design: an agent closing in from the side or from
behind is not seen until it is in front, the fault the paper reports for this controller;
for the same reason the flyer may clip the corner of a passage it turns into, which is
beside it when it gets there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sessgan_controllers.altitude_control import AltitudeHold, with_climb
from sessgan_controllers.controller_interface import (
    STOP,
    Goal,
    RobotState,
    ScanData,
    VelocityCommand,
    parameter,
    wrap_angle,
)
from sessgan_controllers.costmap import FREE, LOW_OBSTACLE
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.route_guidance import (
    RouteGuidanceConfig,
    RouteGuidanceParameters,
    RouteGuide,
    RouteGuidedController,
)
from sessgan_core.validation import require_non_negative, require_positive


@dataclass
class VelocityProjectionConfig(RouteGuidanceParameters):
    """Parameters of :class:`VelocityProjectionController` (each becomes a ROS parameter)."""

    robot_radius: float = parameter(0.2, 'Radius of the flyer footprint in m.')
    safety_margin: float = parameter(
        0.15, 'Clearance in m kept between the flyer footprint and obstacles in view.')
    field_of_view: float = parameter(
        math.radians(60.0), 'Full angle in rad of the cone around the motion direction in '
        'which obstacles are considered.')
    look_ahead_distance: float = parameter(
        1.0, 'Look-ahead in m of the projection at rest.')
    look_ahead_time: float = parameter(
        1.0, 'Extra look-ahead in s per m/s of current speed.')
    max_speed: float = parameter(1.5, 'Maximum planar speed in m/s.')
    arrival_gain: float = parameter(
        0.8, 'Speed in m/s per m of goal distance when close to the goal (1/s).')
    clearance_gain: float = parameter(
        1.0, 'Speed in m/s per m of clearance to the nearest point in view (1/s).')
    min_speed: float = parameter(
        0.1, 'Speed in m/s below which the flyer counts as at rest and looks all around.')
    candidate_count: int = parameter(
        72, 'Number of candidate motion directions over the full turn.')
    yaw_gain: float = parameter(
        1.0, 'Yaw rate in rad/s per rad of heading error towards the motion direction '
        '(0 keeps the heading).')
    max_yaw_rate: float = parameter(1.5, 'Maximum yaw rate in rad/s.')
    goal_tolerance: float = parameter(0.15, 'Distance in m to the goal at which the flyer stops.')
    cruise_altitude: float = parameter(
        0.95, 'Altitude in m (underside above the ground) the flyer climbs to and holds.')
    takeoff_altitude: float = parameter(
        0.45, 'Altitude in m below which the flyer only climbs (above the 0.3 m low obstacles).')
    climb_gain: float = parameter(1.0, 'Climb rate in m/s per m of altitude error (1/s).')
    max_climb_rate: float = parameter(1.0, 'Largest climb or descent rate commanded in m/s.')

    def altitude_hold(self) -> AltitudeHold:
        """The altitude control these parameters ask for."""
        return AltitudeHold(cruise_altitude=self.cruise_altitude,
                            takeoff_altitude=self.takeoff_altitude, climb_gain=self.climb_gain,
                            max_climb_rate=self.max_climb_rate)

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first parameter out of range."""
        for name in ('robot_radius', 'field_of_view', 'look_ahead_distance', 'max_speed',
                     'arrival_gain', 'clearance_gain', 'min_speed', 'max_yaw_rate',
                     'goal_tolerance'):
            require_positive(name, getattr(self, name), InvalidConfigError)
        for name in ('safety_margin', 'look_ahead_time', 'yaw_gain'):
            require_non_negative(name, getattr(self, name), InvalidConfigError)
        self.validate_route_parameters()
        if self.field_of_view > 2.0 * math.pi:
            raise InvalidConfigError(
                f'field_of_view must be at most 2 pi, got {self.field_of_view}')
        if not isinstance(self.candidate_count, int) or self.candidate_count < 4:
            raise InvalidConfigError(
                f'candidate_count must be an integer >= 4, got {self.candidate_count!r}')
        self.altitude_hold().validate()

    def route_guidance(self) -> RouteGuidanceConfig:
        """The route guidance these parameters ask for (the flyer crosses low obstacles)."""
        return self.route_guidance_for(self.robot_radius, (FREE, LOW_OBSTACLE))


@dataclass(frozen=True)
class ProjectionDecision:
    """What one step saw and decided (for tests and logs)."""

    direction: float | None
    """Chosen body-frame motion direction in rad; None when braking or at the goal."""
    reference: float
    """Body-frame direction the field of view was centred on in rad."""
    obstacles_in_view: int
    """Scan points inside the field of view and look-ahead of the chosen direction
    (of the reference direction when braking)."""
    command: VelocityCommand


class VelocityProjectionController(RouteGuidedController):
    """Velocity-projection avoidance; see the module docstring. Keeps only its route between
    steps."""

    def __init__(self, config: VelocityProjectionConfig | None = None) -> None:
        self.config = config or VelocityProjectionConfig()
        self.config.validate()
        self.guide = RouteGuide(self.config.route_guidance())
        self.altitude = self.config.altitude_hold()
        count = self.config.candidate_count
        self._ring = -math.pi + (2.0 * math.pi / count) * np.arange(count)

    def decide(self, scan: ScanData, state: RobotState, goal: Goal) -> ProjectionDecision:
        """Run one step and return the full decision: take off first, then fly the planar
        velocity projection at the cruise altitude."""
        if goal.distance_from(state) <= self.config.goal_tolerance:
            return ProjectionDecision(None, 0.0, 0, STOP)
        climb = self.altitude.climb_rate(state.z)
        if not self.altitude.airborne(state.z):
            reference = math.atan2(state.vy, state.vx) if state.speed > 0.0 else 0.0
            return ProjectionDecision(None, reference, 0, VelocityCommand(vz=climb))
        decision = self._decide_planar(scan, state, goal)
        return with_climb(decision, climb)

    def _decide_planar(self, scan: ScanData, state: RobotState,
                       goal: Goal) -> ProjectionDecision:
        """One step of the planar velocity projection (see the module docstring)."""
        config = self.config
        goal_distance, goal_bearing = goal.in_body_frame(state)
        speed = state.speed
        moving = speed >= config.min_speed
        reference = math.atan2(state.vy, state.vx) if moving else goal_bearing
        if goal_distance <= config.goal_tolerance:
            return ProjectionDecision(None, reference, 0, STOP)
        waypoint = self.guide.waypoint(state, goal)
        goal_distance, goal_bearing = waypoint.target.in_body_frame(state)
        if not moving:
            reference = goal_bearing
        look_ahead = config.look_ahead_distance + config.look_ahead_time * speed
        half_view = 0.5 * config.field_of_view
        if moving and not waypoint.is_goal \
                and abs(wrap_angle(goal_bearing - reference)) > half_view:
            # The route turns out of view (a side passage): stop to look that way first.
            return ProjectionDecision(None, reference, 0, self._brake(reference))
        angles, ranges = scan.points()
        near = ranges <= look_ahead + config.robot_radius
        angles, ranges = angles[near], ranges[near]

        corridor = config.robot_radius + config.safety_margin
        ring_free = ~self._blocked_ring(angles, ranges, look_ahead, corridor, half_view)
        if moving:
            ring_free &= np.abs(wrap_angle(self._ring - reference)) <= half_view
        # The goal direction is checked on its own: its sweep ends at the goal, and its
        # margin is capped at half the goal's own clearance, so a goal by a wall stays
        # reachable.
        goal_free = not moving or abs(wrap_angle(goal_bearing - reference)) <= half_view
        if goal_free and len(ranges):
            relative = angles - goal_bearing
            along, across = ranges * np.cos(relative), ranges * np.sin(relative)
            goal_clearance = float(np.min(np.hypot(along - goal_distance, across)))
            margin = min(config.safety_margin,
                         max(0.0, 0.5 * (goal_clearance - config.robot_radius)))
            excess = along - np.clip(along, 0.0, min(look_ahead, goal_distance))
            in_view = along >= ranges * math.cos(half_view)
            reach = (config.robot_radius + margin) ** 2
            goal_free = not bool(np.any(in_view & (excess * excess + across * across < reach)))
        candidates = np.concatenate(([goal_bearing], self._ring))
        free = np.flatnonzero(np.concatenate(([goal_free], ring_free)))
        if len(free) == 0:
            seen = int((np.cos(angles - reference) >= math.cos(half_view)).sum())
            return ProjectionDecision(None, reference, seen, self._brake(reference))
        offsets = np.abs(wrap_angle(candidates[free] - goal_bearing))
        best = int(free[np.argmin(offsets)])
        direction = float(candidates[best])
        view_ranges = ranges[np.cos(angles - direction) >= math.cos(half_view)]
        speed_limit = config.max_speed
        if len(view_ranges):
            clearance = float(view_ranges.min()) - config.robot_radius
            speed_limit = min(speed_limit, config.clearance_gain * max(clearance, 0.0))
        if waypoint.is_goal:
            speed_limit = min(speed_limit, config.arrival_gain * goal_distance)
        target_speed = max(0.0, speed_limit)
        command = VelocityCommand(
            vx=target_speed * math.cos(direction),
            vy=target_speed * math.sin(direction),
            wz=self._yaw_rate(direction),
        )
        return ProjectionDecision(direction, reference, len(view_ranges), command)

    def _blocked_ring(self, angles: np.ndarray, ranges: np.ndarray, length: float,
                      corridor: float, half_view: float) -> np.ndarray:
        """Which ring directions a point in their view blocks: it lies closer than
        ``corridor`` to the segment of ``length`` the flyer would sweep along them.

        For a point at range r the blocked directions form an interval around its
        bearing of half-width asin(corridor / r) while the segment reaches past the
        point, acos((r^2 + length^2 - corridor^2) / (2 r length)) beyond its end; at
        most the half field of view. Intervals are marked on the ring with a circular
        difference array.
        """
        count = len(self._ring)
        blocked = np.zeros(count, dtype=bool)
        if len(ranges) == 0:
            return blocked
        radius = np.maximum(ranges, 1e-9)
        side = np.arcsin(np.minimum(1.0, corridor / radius))
        with np.errstate(invalid='ignore', divide='ignore'):
            cap = np.arccos(np.clip(
                (radius ** 2 + length ** 2 - corridor ** 2) / (2.0 * radius * length), -1.0, 1.0))
        width = np.where(radius ** 2 < length ** 2 + corridor ** 2, side, cap)
        width = np.where(radius <= corridor, half_view, np.minimum(width, half_view))
        reaches = radius - length < corridor
        step = 2.0 * math.pi / count
        low = np.ceil((angles[reaches] - width[reaches] + math.pi) / step).astype(int)
        high = np.floor((angles[reaches] + width[reaches] + math.pi) / step).astype(int)
        spans = high - low + 1
        if np.any(spans >= count):
            return np.ones(count, dtype=bool)
        marked = spans > 0
        low, high = low[marked] % count, high[marked] % count
        difference = np.zeros(count + 1, dtype=int)
        np.add.at(difference, low, 1)
        np.add.at(difference, high + 1, -1)
        difference[0] += int(np.count_nonzero(low > high))
        return np.cumsum(difference[:count]) > 0

    def _brake(self, reference: float) -> VelocityCommand:
        """Hover in place (the flyer's inertia decides how far it still drifts)."""
        return VelocityCommand(0.0, 0.0, self._yaw_rate(reference))

    def _yaw_rate(self, direction: float) -> float:
        limit = self.config.max_yaw_rate
        return min(limit, max(-limit, self.config.yaw_gain * wrap_angle(direction)))
