"""Nearness-Diagram (ND) navigation for a circular ground robot (differential drive or tricycle).

Minguez, J. and Montano, L., "Nearness Diagram (ND) Navigation: Collision
Avoidance in Troublesome Scenarios", IEEE Trans. Robotics and Automation 20(1),
2004. Where the paper leaves a detail open (the reachability test of a region,
the LS1/LS2 and HSWR laws, the motion generator for non-holonomic robots), this
follows the authors' reference implementation (Minguez's ``nd.c``, shipped with
the Player robot server), for a circular robot.

One step, towards the waypoint of a route on the map
(:mod:`~sessgan_controllers.route_guidance`; the goal itself without a map or with
``use_map`` false, when ND is purely reactive and dead ends trap it, as in Player where
``nd`` ran behind the ``wavefront`` planner):

1. Sectorise the scan: the nearest obstacle point in each of ``sector_count``
   sectors around the robot (the PND; a sector without a return is free).
2. Find discontinuities between adjacent sectors: a free sector next to an
   occupied one, or two obstacle distances differing by at least
   ``gap_threshold`` (the robot's diameter: the robot fits between them).
   Regions are the runs of sectors between discontinuities; a discontinuity is
   *rising* seen from the deeper side, and that region is a valley.
3. Select the region: the goal's own direction when the goal is in sight and
   reachable, otherwise the rising discontinuity angularly closest to the goal
   whose intermediate target is reachable (no pair of obstacle points on either
   side of the straight path closer than ``gap_threshold``).
4. Classify the situation: Low Safety when obstacles are within
   ``security_distance`` of the robot's boundary (LS1: on one side of the
   selected direction, LS2: on both), otherwise High Safety (HSGR: goal in the
   region, HSWR: wide region of more than a quarter turn, HSNR: narrow region).
   LS1 with the goal in the region blends from the goal direction (the
   reference implementation's LSG case), so the five situations cover all.
5. Apply the situation's action law to get the motion direction theta, then
   the motion generator of the reference implementation for non-holonomic
   robots, with theta clipped to [-pi/2, pi/2]::

       c = max(min_speed_factor, min(1, d_obs / security_distance))
       v = v_max * c * cos(theta)
       w = w_max * c * sin(theta)

   where d_obs is the distance from the robot's boundary to the nearest obstacle
   in the security zone (c = 1 without one).
6. Protective field (not in ND; every industrial AGV has one): the forward speed is at
   most the one from which the robot, braking at ``braking_deceleration``, stops
   ``stop_distance`` short of the nearest return straight ahead while that return comes
   closer at ``obstacle_speed``. Without it ND at 1 m/s cannot stop inside its 0.2 m
   security distance and drives into every robot coming the other way.
7. A robot that cannot turn in place (``min_turn_radius`` > 0, sessgan_sim's
   ``tricycle``): the forward speed is raised to ``|w| * min_turn_radius`` (at most v_max)
   and, after the protective field, the yaw rate capped at ``v / min_turn_radius``. Where
   the protective field leaves no room ahead for the turn, it backs up at
   ``reverse_speed`` on the arc that turns it the same way (a three-point turn), as far as
   the protective field behind it allows.

**Intended weakness** (what a test generator should rediscover): narrow-space turns. The
algorithm is reactive and plans for a point that can move in any direction; the motion
generator only turns in place when theta reaches +-90 degrees and otherwise drives an arc
whose forward speed never drops below ``min_speed_factor * v_max * cos(theta)``, while the
turn rate shrinks with the same factor near obstacles. In a corridor barely wider than the
robot, a sharp turn therefore cuts the inner corner or overshoots into the outer wall: the
narrow-space fault of the paper. The protective field looks straight ahead only, so it
does not see the corner an arc cuts. In open space ND is fine.

**Intended weakness of the tricycle** (``tricycle_nearness_diagram``): it needs room to
turn. Where ND asks for a turn on the spot (an obstacle ahead, the waypoint to the side)
it must drive arcs of at least ``min_turn_radius``, forwards and backwards: in a tight
passage its arcs overshoot into the walls, and with no room ahead or behind it stays
stuck, the paper's "unable to turn in place" fault.
"""

from __future__ import annotations

import enum
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
)
from sessgan_core.validation import require_non_negative, require_positive

FAR_TARGET = 1e6
"""Distance in metres of the intermediate target behind an open (free) discontinuity."""


@dataclass
class NearnessDiagramConfig(RouteGuidanceParameters):
    """Parameters of :class:`NearnessDiagramController` (each becomes a ROS parameter)."""

    robot_radius: float = parameter(0.2, 'Radius of the circular robot footprint in m.')
    security_distance: float = parameter(
        0.2, 'Security distance D_s in m from the robot boundary; closer obstacles mean Low '
        'Safety and slow the robot down.')
    max_linear_speed: float = parameter(1.0, 'Maximum forward speed v_max in m/s.')
    max_angular_speed: float = parameter(2.0, 'Maximum yaw rate w_max in rad/s.')
    sector_count: int = parameter(
        144, 'Number of sectors of the nearness diagram over the full turn.')
    min_speed_factor: float = parameter(
        0.4, 'Floor of the obstacle speed factor c of the motion generator (0..1); the robot '
        'keeps v_max * c * cos(theta) forward speed even next to obstacles.')
    gap_threshold: float = parameter(
        0.0, 'Depth jump in m that makes a discontinuity and the narrowest passage the robot '
        'may enter; 0 means the robot diameter (2 * robot_radius).')
    goal_tolerance: float = parameter(
        0.15, 'Distance in m to the goal at which the robot stops.')
    braking_deceleration: float = parameter(
        0.8, 'Deceleration in m/s^2 the forward speed allows for stopping stop_distance short of '
        'the nearest return straight ahead; 0 turns this limit off.')
    stop_distance: float = parameter(
        0.1, 'Gap in m to the nearest return straight ahead at which the robot has stopped.')
    obstacle_speed: float = parameter(
        0.5, 'Speed in m/s at which a return straight ahead may come closer while the robot '
        'brakes (another robot driving towards it).')
    min_turn_radius: float = parameter(
        0.0, 'Tightest turn in m of a robot that cannot turn in place (a steered drive wheel); '
        'the forward speed is raised to what the turn needs and the yaw rate capped at speed / '
        'radius. 0: the robot turns in place.')
    reverse_speed: float = parameter(
        0.0, 'Robots that cannot turn in place: speed in m/s at which to back up on an arc '
        'turning the wanted way when there is no room ahead for the turn; 0: never reverse.')

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first parameter out of range."""
        for name in ('robot_radius', 'security_distance', 'max_linear_speed',
                     'max_angular_speed', 'goal_tolerance'):
            require_positive(name, getattr(self, name), InvalidConfigError)
        if not 0.0 <= self.min_speed_factor <= 1.0:
            raise InvalidConfigError(
                f'min_speed_factor must be in [0, 1], got {self.min_speed_factor}')
        if not isinstance(self.sector_count, int) or self.sector_count < 8:
            raise InvalidConfigError(
                f'sector_count must be an integer >= 8, got {self.sector_count!r}')
        for name in ('gap_threshold', 'braking_deceleration', 'stop_distance',
                     'obstacle_speed', 'min_turn_radius', 'reverse_speed'):
            require_non_negative(name, getattr(self, name), InvalidConfigError)
        self.validate_route_parameters()

    def route_guidance(self) -> RouteGuidanceConfig:
        """The route guidance these parameters ask for."""
        return self.route_guidance_for(self.robot_radius)

    @property
    def effective_gap_threshold(self) -> float:
        """The discontinuity threshold in metres actually used."""
        return self.gap_threshold if self.gap_threshold > 0.0 else 2.0 * self.robot_radius


@dataclass
class TricycleNearnessDiagramConfig(NearnessDiagramConfig):
    """ND for sessgan_sim's ``tricycle`` robot, which cannot turn in place: the same
    parameters, turning no tighter than its 0.5 m radius, and slower (a turn that the robot
    sees coming late needs room, the faster the more)."""

    max_linear_speed: float = parameter(0.8, 'Maximum forward speed v_max in m/s.')
    min_turn_radius: float = parameter(
        0.5, 'Tightest turn in m of the robot (it cannot turn in place); the forward speed is '
        'raised to what a turn needs and the yaw rate capped at speed / radius.')
    reverse_speed: float = parameter(
        0.2, 'Speed in m/s at which the robot backs up on an arc turning the wanted way when '
        'there is no room ahead for the turn; 0: never reverse.')


class Situation(enum.Enum):
    """The ND situations, plus the two outcomes that produce no motion law."""

    LOW_SAFETY_1 = 'LS1'
    LOW_SAFETY_2 = 'LS2'
    HIGH_SAFETY_GOAL_IN_REGION = 'HSGR'
    HIGH_SAFETY_WIDE_REGION = 'HSWR'
    HIGH_SAFETY_NARROW_REGION = 'HSNR'
    GOAL_REACHED = 'goal_reached'
    NO_REGION = 'no_region'
    """No reachable valley: the robot stops (the reference implementation's failure return)."""


@dataclass(frozen=True)
class Region:
    """A run of sectors between two discontinuities, indices counter-clockwise."""

    first: int
    """Sector at the clockwise (right) end."""
    last: int
    """Sector at the counter-clockwise (left) end."""
    width: int
    """Number of sectors."""


@dataclass(frozen=True)
class NearnessDiagramDecision:
    """What one ND step saw and decided (for tests, logs and visualisation)."""

    situation: Situation
    direction: float
    """Motion direction theta in the body frame in radians, before clipping to +-pi/2."""
    target_direction: float
    """Direction of the selected region's target (goal or discontinuity) in radians."""
    region: Region | None
    goal_directed: bool
    """True when the region's target is the goal itself."""
    closest_obstacle: float
    """Distance in m from the robot boundary to the nearest obstacle in the security zone
    (inf when none)."""
    command: VelocityCommand


class NearnessDiagramController(RouteGuidedController):
    """ND navigation; see the module docstring. Keeps only its route between steps."""

    def __init__(self, config: NearnessDiagramConfig | None = None) -> None:
        self.config = config or NearnessDiagramConfig()
        self.config.validate()
        self.guide = RouteGuide(self.config.route_guidance())
        count = self.config.sector_count
        self._sector_width = 2.0 * math.pi / count
        # Sector i is centred on -pi + (i + 0.5) * width: index grows counter-clockwise.
        self._sector_angles = -math.pi + (np.arange(count) + 0.5) * self._sector_width
        self._sector_directions = np.stack(
            (np.cos(self._sector_angles), np.sin(self._sector_angles)), axis=1)
        self._beam_map_key: tuple[int, float, float] | None = None
        self._beam_sector = np.zeros(0, dtype=int)
        self._fill_beam = np.zeros(0, dtype=int)

    # ----------------------------------------------------------------------------------------
    # The ND step

    def decide(self, scan: ScanData, state: RobotState, goal: Goal) -> NearnessDiagramDecision:
        """Run one ND step and return the full decision."""
        config = self.config
        goal_distance, goal_bearing = goal.in_body_frame(state)
        if goal_distance <= config.goal_tolerance:
            return NearnessDiagramDecision(
                Situation.GOAL_REACHED, 0.0, goal_bearing, None, True, math.inf, STOP)
        goal_distance, goal_bearing = self.guide.waypoint(state, goal).target.in_body_frame(
            state)
        nearness = self.sector_distances(scan)
        selection = self._select_region(nearness, goal_distance, goal_bearing)
        if selection is None:
            return NearnessDiagramDecision(
                Situation.NO_REGION, 0.0, goal_bearing, None, False, math.inf, STOP)
        region, target_direction, goal_directed, boundary = selection
        situation, direction, closest = self._action(
            nearness, region, target_direction, goal_directed, boundary)
        command = self._limit(self._motion(direction, closest), scan)
        return NearnessDiagramDecision(
            situation, direction, target_direction, region, goal_directed, closest, command)

    def sector_distances(self, scan: ScanData) -> np.ndarray:
        """Distance in m to the nearest obstacle of each sector; NaN where the sector is free.

        Sectors the scan's beams do not reach (sparse scans) take the nearest beam's
        reading; sectors outside the scan's field of view are free. Distances are kept
        just outside the robot's radius, like the reference implementation does.
        """
        ranges = np.asarray(scan.ranges, dtype=float)
        self._update_beam_map(scan)
        valid = scan.valid()
        nearness = np.full(self.config.sector_count, np.inf)
        np.minimum.at(nearness, self._beam_sector[valid], ranges[valid])
        empty = self._fill_beam >= 0
        fill = self._fill_beam[empty]
        nearness[empty] = np.where(valid[fill], ranges[fill], np.inf)
        nearness[~np.isfinite(nearness)] = np.nan
        floor = self.config.robot_radius + 0.01
        return np.where(nearness < floor, floor, nearness)

    def _update_beam_map(self, scan: ScanData) -> None:
        key = (len(scan.ranges), float(scan.angle_min), float(scan.angle_increment))
        if key == self._beam_map_key:
            return
        count = self.config.sector_count
        angles = scan.angles()
        self._beam_sector = np.floor((angles + math.pi) / self._sector_width).astype(int) % count
        hit = np.zeros(count, dtype=bool)
        hit[self._beam_sector] = True
        # For sectors no beam falls in, the nearest beam if it lies within one beam spacing.
        fill = np.full(count, -1, dtype=int)
        if len(angles):
            spacing = max(abs(scan.angle_increment), 1e-9)
            for sector in np.flatnonzero(~hit):
                offsets = np.abs(wrap_angle(angles - self._sector_angles[sector]))
                nearest = int(np.argmin(offsets))
                if offsets[nearest] <= spacing:
                    fill[sector] = nearest
        self._fill_beam = fill
        self._beam_map_key = key

    # ----------------------------------------------------------------------------------------
    # Region selection

    def _sector_of(self, angle: float) -> int:
        return int(math.floor((wrap_angle(angle) + math.pi) / self._sector_width)) \
            % self.config.sector_count

    def _discontinuities(self, nearness: np.ndarray) -> list[tuple[int, int]]:
        """Discontinuities as (valley sector, outer sector) pairs of adjacent sectors.

        The valley side is the free or deeper one (the discontinuity is rising seen
        from there); the outer side holds the nearer obstacle.
        """
        following = np.concatenate((nearness[1:], nearness[:1]))
        free, free_next = np.isnan(nearness), np.isnan(following)
        with np.errstate(invalid='ignore'):
            jump = np.abs(nearness - following) >= self.config.effective_gap_threshold
            deeper = nearness > following  # False where either side is free
        is_disc = (free != free_next) | (~free & ~free_next & jump)
        here = np.flatnonzero(is_disc)
        after = (here + 1) % self.config.sector_count
        valley_here = free[here] | (~free_next[here] & deeper[here])
        valleys = np.where(valley_here, here, after).tolist()
        outers = np.where(valley_here, after, here).tolist()
        return list(zip(valleys, outers, strict=True))

    def _region_around(self, sector: int, disc_indices: list[int]) -> Region:
        """The region containing ``sector``, given sorted discontinuity indices."""
        count = self.config.sector_count
        if not disc_indices:
            return Region(0, count - 1, count)
        # Region boundaries: a discontinuity at i separates sector i (left end of one region)
        # from i + 1 (right end of the next).
        position = np.searchsorted(disc_indices, sector)  # first disc index >= sector
        last = disc_indices[position % len(disc_indices)]
        first = (disc_indices[(position - 1) % len(disc_indices)] + 1) % count
        width = (last - first) % count + 1
        return Region(first, last, width)

    def _select_region(
        self, nearness: np.ndarray, goal_distance: float, goal_bearing: float
    ) -> tuple[Region, float, bool, tuple[int, bool] | None] | None:
        """(region, target direction, goal directed, boundary) or None when none is reachable.

        ``boundary`` is (outer sector, valley lies counter-clockwise of it) for a
        discontinuity target, None for the goal.
        """
        count = self.config.sector_count
        points = self._obstacle_points(nearness)
        discontinuities = self._discontinuities(nearness)
        # A discontinuity between sectors i and i + 1 is indexed by i.
        disc_indices = sorted(valley if (outer - valley) % count == 1 else outer
                              for valley, outer in discontinuities)
        goal_sector = self._sector_of(goal_bearing)
        goal_in_sight = bool(np.isnan(nearness[goal_sector])) \
            or goal_distance <= nearness[goal_sector]
        if goal_in_sight and self._reachable(points, goal_distance, goal_bearing):
            return self._region_around(goal_sector, disc_indices), goal_bearing, True, None
        # Rising discontinuities, closest to the goal direction first; the first reachable wins.
        offsets = [abs(wrap_angle(float(self._sector_angles[valley]) - goal_bearing))
                   for valley, _ in discontinuities]
        for index in np.argsort(offsets, kind='stable'):
            valley, outer = discontinuities[index]
            target_distance, target_angle = self._gap_target(nearness, valley, outer)
            if self._reachable(points, target_distance, target_angle):
                region = self._region_around(valley, disc_indices)
                valley_ccw = (valley - outer) % count == 1
                return region, target_angle, False, (outer, valley_ccw)
        return None

    def _gap_target(self, nearness: np.ndarray, valley: int, outer: int) -> tuple[float, float]:
        """(distance, angle) of the intermediate target that a discontinuity offers."""
        outer_distance = float(nearness[outer])
        outer_angle = float(self._sector_angles[outer])
        if np.isnan(nearness[valley]):
            # Open gap: far away, half way between the obstacle edge and the free sector.
            valley_angle = float(self._sector_angles[valley])
            bisector = outer_angle + 0.5 * wrap_angle(valley_angle - outer_angle)
            return FAR_TARGET, wrap_angle(bisector)
        valley_distance = float(nearness[valley])
        valley_angle = float(self._sector_angles[valley])
        x = 0.5 * (outer_distance * math.cos(outer_angle)
                   + valley_distance * math.cos(valley_angle))
        y = 0.5 * (outer_distance * math.sin(outer_angle)
                   + valley_distance * math.sin(valley_angle))
        return math.hypot(x, y), math.atan2(y, x)

    def _obstacle_points(self, nearness: np.ndarray) -> np.ndarray:
        occupied = ~np.isnan(nearness)
        distances = nearness[occupied]
        return self._sector_directions[occupied] * distances[:, None]

    def _reachable(self, points: np.ndarray, distance: float, angle: float) -> bool:
        """Whether a straight path of the robot's width leads to the target (ND's check).

        Obstacle points in a band of half-width ``gap_threshold`` along the path are
        split into left and right; the target is unreachable when it lies within
        half the threshold of a point or when a left and a right point are closer
        than the threshold (the robot cannot pass between them).
        """
        if len(points) == 0:
            return True
        gap = self.config.effective_gap_threshold
        cos_a, sin_a = math.cos(angle), math.sin(angle)
        along = points[:, 0] * cos_a + points[:, 1] * sin_a
        across = -points[:, 0] * sin_a + points[:, 1] * cos_a
        band = (along >= 0.0) & (along < distance) & (np.abs(across) <= gap)
        if not band.any():
            return True
        along, across = along[band], across[band]
        if np.any(np.hypot(along - distance, across) < 0.5 * gap):
            return False
        left = across > 0.0
        if not left.any() or left.all():
            return True
        left_points = np.stack([along[left], across[left]], axis=1)
        right_points = np.stack([along[~left], across[~left]], axis=1)
        separation = np.linalg.norm(left_points[:, None, :] - right_points[None, :, :], axis=2)
        return not bool(np.any(separation < gap))

    # ----------------------------------------------------------------------------------------
    # Situations, action laws and motion law

    def _action(
        self,
        nearness: np.ndarray,
        region: Region,
        target_direction: float,
        goal_directed: bool,
        boundary: tuple[int, bool] | None,
    ) -> tuple[Situation, float, float]:
        """(situation, motion direction, closest obstacle distance to the robot boundary)."""
        config = self.config
        clearance = nearness - config.robot_radius
        with np.errstate(invalid='ignore'):
            in_zone = ~np.isnan(clearance) & (clearance <= config.security_distance)
        relative = wrap_angle(self._sector_angles - target_direction)
        left = in_zone & (relative >= 0.0)
        right = in_zone & (relative < 0.0)
        closest = float(np.min(clearance[in_zone])) if in_zone.any() else math.inf
        wide = region.width > config.sector_count // 4
        if not in_zone.any():
            if goal_directed:
                return Situation.HIGH_SAFETY_GOAL_IN_REGION, target_direction, closest
            if wide:
                return Situation.HIGH_SAFETY_WIDE_REGION, self._wide_direction(
                    nearness, boundary), closest
            return Situation.HIGH_SAFETY_NARROW_REGION, self._region_bisector(region), closest
        if left.any() and right.any():
            left_sector = int(np.flatnonzero(left)[np.argmin(clearance[left])])
            right_sector = int(np.flatnonzero(right)[np.argmin(clearance[right])])
            left_ratio = clearance[left_sector] / config.security_distance
            right_ratio = clearance[right_sector] / config.security_distance
            # LS2: lean away from the relatively closer side, towards the side's limit at 90 deg.
            balance = (left_ratio - right_ratio) / (left_ratio + right_ratio)
            if left_ratio <= right_ratio:
                direction = target_direction + balance * (target_direction + math.pi / 2.0)
            else:
                direction = target_direction + balance * (math.pi / 2.0 - target_direction)
            return Situation.LOW_SAFETY_2, wrap_angle(direction), closest
        # LS1: blend the region's direction with the direction away from the one-sided obstacle.
        if goal_directed:
            partial = target_direction
        elif wide:
            partial = self._wide_direction(nearness, boundary)
        else:
            partial = self._region_bisector(region)
        side = left if left.any() else right
        sector = int(np.flatnonzero(side)[np.argmin(clearance[side])])
        ratio = float(clearance[sector] / config.security_distance)
        away = partial + wrap_angle(self._sector_angles[sector] + math.pi - partial)
        direction = partial * ratio + away * (1.0 - ratio)
        direction = min(max(direction, -math.pi + 0.01), math.pi - 0.01)
        return Situation.LOW_SAFETY_1, direction, closest

    def _region_bisector(self, region: Region) -> float:
        centre = (region.first + (region.width - 1) / 2.0) % self.config.sector_count
        return wrap_angle(-math.pi + (centre + 0.5) * self._sector_width)

    def _wide_direction(self, nearness: np.ndarray, boundary: tuple[int, bool] | None) -> float:
        """HSWR: pass the discontinuity's obstacle at half a gap plus the security distance."""
        if boundary is None:  # not reached: a goal-directed region follows the goal bearing
            return 0.0
        outer, valley_ccw = boundary
        distance = float(nearness[outer])
        margin = math.atan2(
            0.5 * self.config.effective_gap_threshold + self.config.security_distance, distance)
        angle = float(self._sector_angles[outer])
        return wrap_angle(angle + margin if valley_ccw else angle - margin)

    def _stopping_speed(self, scan: ScanData, backwards: bool = False) -> float:
        """Forward (``backwards``: reverse) speed in m/s from which the robot stops
        ``stop_distance`` short of the nearest return in its path straight ahead (behind):
        its protective field."""
        config = self.config
        if config.braking_deceleration <= 0.0:
            return math.inf
        angles, ranges = scan.points()
        along, across = ranges * np.cos(angles), np.abs(ranges * np.sin(angles))
        if backwards:
            along = -along
        radius = config.robot_radius
        ahead = (along > 0.0) & (across < radius)
        if not ahead.any():
            return math.inf
        # Distance the disc can move forward before touching each return.
        gaps = along[ahead] - np.sqrt(radius * radius - across[ahead] ** 2)
        room = max(0.0, float(gaps.min()) - config.stop_distance)
        # Stop within the room while the return closes in at obstacle_speed meanwhile:
        # v^2 / (2 a) + obstacle_speed * v / a <= room.
        closing = config.obstacle_speed
        return -closing + math.sqrt(closing * closing
                                    + 2.0 * config.braking_deceleration * room)

    def _limit(self, command: VelocityCommand, scan: ScanData) -> VelocityCommand:
        """The motion law's command within the protective field and, for a robot that cannot
        turn in place, on an arc no tighter than ``min_turn_radius`` (backing up to turn
        where there is no room ahead)."""
        config = self.config
        radius = config.min_turn_radius
        linear, angular = command.vx, command.wz
        if radius > 0.0:
            # It turns only while moving: drive as fast as the turn asks for.
            linear = max(linear, min(config.max_linear_speed, abs(angular) * radius))
        stopping_speed = self._stopping_speed(scan)
        if radius > 0.0 and config.reverse_speed > 0.0 and angular != 0.0 \
                and stopping_speed < min(linear, config.reverse_speed):
            # No room ahead for the turn: back up on the arc that turns the same way.
            reverse = min(config.reverse_speed, self._stopping_speed(scan, backwards=True))
            return VelocityCommand(vx=-reverse, vy=0.0,
                                   wz=math.copysign(reverse / radius, angular))
        linear = min(linear, stopping_speed)
        if radius > 0.0:
            limit = linear / radius
            angular = min(max(angular, -limit), limit)
        return VelocityCommand(vx=linear, vy=0.0, wz=angular)

    def _motion(self, direction: float, closest: float) -> VelocityCommand:
        """The reference implementation's non-holonomic motion generator (module docstring)."""
        config = self.config
        theta = min(max(direction, -math.pi / 2.0), math.pi / 2.0)
        safety = 1.0 if not math.isfinite(closest) \
            else min(1.0, max(0.0, closest) / config.security_distance)
        factor = max(config.min_speed_factor, safety)
        linear = max(0.0, config.max_linear_speed * factor * math.cos(theta))
        angular = config.max_angular_speed * factor * math.sin(theta)
        return VelocityCommand(vx=linear, vy=0.0, wz=angular)
