"""What an episode needs besides the Environment (:class:`EpisodeConfig`), its validation, the
scenario's defaults and the rule of the default time limit."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field

from sessgan_core.environment import Environment
from sessgan_core.scenarios import Scenario, get_scenario
from sessgan_core.validation import require_positive
from sessgan_sim.agents import AgentConfig
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.sensors import LidarConfig, RangeFinderConfig
from sessgan_sim.world import WorldStyle

ROUTE_TIME_FACTOR = 4.0
"""Default time limits allow driving the certified route at a quarter of the top speed."""

MAX_TIME_LIMIT = 3600.0
"""Sim seconds: the longest time limit a user may ask for (30 x the longest scenario default,
72 000 ticks at 20 Hz). The wall-clock timeout of an episode grows with it, so a limit like
1e9 s would leave a stalled worker undetected for ever; limits derived from a route or a
mission's legs are not bounded by it."""


def check_time_limit(value: float, name: str = 'time limit') -> float:
    """``value`` (sim seconds, 0: the default) as a float, or InvalidConfigError naming
    ``name`` when it is not a number in [0, MAX_TIME_LIMIT]."""
    try:
        limit = float(value)
    except (TypeError, ValueError) as err:
        raise InvalidConfigError(f'{name} must be a number of sim seconds, got {value!r}') \
            from err
    if not (math.isfinite(limit) and 0.0 <= limit <= MAX_TIME_LIMIT):
        raise InvalidConfigError(f'{name} must lie in [0, {MAX_TIME_LIMIT:.0f}] sim seconds '
                                 f'(0: the scenario default), got {value!r}')
    return limit


@dataclass(frozen=True)
class EpisodeConfig:
    """Everything an episode needs besides the Environment. None = the scenario's default.

    Units: seconds, metres, hertz.
    """

    robot: str | None = None
    """Robot model from the registry (sessgan_sim.robots); None: the scenario's robot."""
    robot_params: Mapping[str, float] = field(default_factory=dict)
    """Overrides of the robot model's parameters, e.g. {'max_linear_speed': 0.5}."""
    control_rate_hz: float = 20.0
    """Control ticks per sim second: one command per tick."""
    physics_rate_hz: float = 100.0
    """Physics steps per sim second, rounded to a whole number of steps per tick. 100 Hz
    keeps a car at 12 m/s moving 12 cm per step, well inside any barrier's 1 m cell."""
    time_limit: float | None = None
    """Sim seconds before the episode ends with outcome timeout. None: the scenario's limit,
    raised for the environment's route and mission (:meth:`time_limit_for`)."""
    proximity_distance: float | None = None
    """Clearance below which time counts as proximity time."""
    clearance_range: float | None = None
    """Farthest clearance measured, at least the proximity distance: min_clearance is capped
    here. None: the proximity distance (the cheapest query)."""
    lidar: LidarConfig = field(default_factory=LidarConfig)
    range_finder: RangeFinderConfig = field(default_factory=RangeFinderConfig)
    """The downward range sensor; only a flying robot has one."""
    dummy_agents: int | None = None
    """Number of moving dummy agents."""
    agents: AgentConfig = field(default_factory=AgentConfig)
    stuck_timeout: float = 30.0
    """Sim seconds neither closer to the goal (a new minimum of the geodesic distance on the
    grid) nor onto new ground before the episode ends with outcome stuck (sessgan_sim.progress);
    <= 0 disables it. 30: a stack with recoveries (Nav2's progress checker gives up after
    10 s, then clears, spins, waits, backs up) gets to recover; until 2026-11-28 it was 10."""
    goal_tolerance: float | None = None
    """Distance of the robot's centre to the goal that counts as reached; None: one cell of
    the scenario."""
    collision_limit: int = 10
    """Collisions that end the episode (outcome collision_limit); 0 disables it."""
    seed: int = 0
    """Seed of every random choice of the episode."""
    world: WorldStyle = field(default_factory=WorldStyle)

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable value."""
        for name in ('control_rate_hz', 'physics_rate_hz'):
            require_positive(f'episode config: {name}', getattr(self, name), InvalidConfigError)
        for name in ('time_limit', 'proximity_distance', 'goal_tolerance', 'clearance_range'):
            if getattr(self, name) is not None:
                require_positive(f'episode config: {name} (or None)', getattr(self, name),
                                 InvalidConfigError)
        if self.physics_rate_hz < self.control_rate_hz:
            raise InvalidConfigError(
                f'episode config: physics_rate_hz ({self.physics_rate_hz}) must be at least '
                f'control_rate_hz ({self.control_rate_hz})')
        if not math.isfinite(self.stuck_timeout):
            raise InvalidConfigError(f'episode config: stuck_timeout must be finite, got '
                                     f'{self.stuck_timeout}')
        counts = (('collision_limit', self.collision_limit), ('seed', self.seed),
                  ('dummy_agents', 0 if self.dummy_agents is None else self.dummy_agents))
        for name, count in counts:
            if not (isinstance(count, numbers.Integral) and count >= 0):
                raise InvalidConfigError(f'episode config: {name} must be an integer >= 0, '
                                         f'got {count!r}')
        self.lidar.validate()
        self.range_finder.validate()
        self.agents.validate()
        self.world.validate()

    def resolved(self, scenario: Scenario) -> EpisodeConfig:
        """This config with every None replaced by the scenario's default."""
        proximity = (self.proximity_distance if self.proximity_distance is not None
                     else scenario.proximity_distance)
        return dataclasses.replace(
            self,
            robot=self.robot if self.robot is not None else scenario.robot,
            time_limit=self.time_limit if self.time_limit is not None else scenario.time_limit,
            proximity_distance=proximity,
            clearance_range=max(self.clearance_range or proximity, proximity),
            dummy_agents=(self.dummy_agents if self.dummy_agents is not None
                          else scenario.dummy_agents),
            goal_tolerance=(self.goal_tolerance if self.goal_tolerance is not None
                            else scenario.cell_size),
        )

    def time_limit_for(self, environment: Environment, top_speed: float) -> float:
        """Sim seconds ``environment``'s episode lasts at most for a robot of ``top_speed``
        m/s: :attr:`time_limit` when given. Else the scenario's, raised to ROUTE_TIME_FACTOR x
        the longest certified route (of every robot under test) / ``top_speed``, so a valid
        test always leaves time to drive its route; a mission gets the scenario's limit per
        leg (at least the route's time) and time for every dwell."""
        if self.time_limit is not None:
            return self.time_limit
        scenario = get_scenario(environment.scenario)
        limit: float = scenario.time_limit
        route_length = max([environment.route_length,
                            *(member.route_length for member in environment.fleet)])
        if route_length > 0:
            limit = max(float(limit or 0.0), ROUTE_TIME_FACTOR * route_length / top_speed)
        if environment.stations:
            limit = (max(scenario.time_limit * environment.legs, float(limit or 0.0))
                     + len(environment.stations) * environment.dwell_time)
        return limit

    @property
    def control_period(self) -> float:
        """Sim seconds per control tick."""
        return 1.0 / self.control_rate_hz

    @property
    def physics_steps_per_tick(self) -> int:
        return max(1, round(self.physics_rate_hz / self.control_rate_hz))

    @property
    def physics_timestep(self) -> float:
        """Sim seconds per physics step (the tick divided into whole steps)."""
        return self.control_period / self.physics_steps_per_tick
