"""Moving dummy agents: other robots in the factory, other flyers in the drone area.

Each agent patrols back and forth along a seeded path through free space: two
random cells of the footprint-free space (walls inflated by the agent's radius)
joined by a 4-connected shortest path (sessgan_core.valid_tests), at a constant
speed. Agents are kinematic: static pybullet bodies moved every physics step,
which the robot under test can hit (a contact counts as a collision) but cannot
push. They move in the robot's plane (ground agents for ground robots, flyers at the
flyer's traffic altitude) and are seen by its lidar when its scan plane cuts them. No
agent starts within ``min_start_distance`` of the robot's start, and no patrol begins or
ends inside the ``keep_clear`` discs the episode names (around the goal and on the certified
route's narrow passages, so an agent never parks where the robot must pass) or anywhere in
such a passage. A patrol may cross a narrow passage but not run along it: an agent shuttling
inside a passage the robot cannot share with it would hold the robot up until the time
limit, a fault of the test; for the same reason a patrol is at least ``PASSAGE_SHARE`` times
as long as what it holds of a passage. An agent that finds no patrol of
``min_patrol_cells`` is not placed.

Two behaviours (``AgentConfig.behaviour``): ``blind`` agents (the default, the paper's) keep
moving whatever is in their way; ``cautious`` agents behave like factory AGVs with a safety
scanner: an agent waits while the robot or another agent stands within ``safety_distance``
ahead of it along its motion, so any contact with a cautious agent is the robot's doing. A
blind agent that touches a robot under test while moving toward it turns back along its
patrol, as a person who bumps into a robot steps back: it never drags or shoves the robot
further (a kinematic body would push it metres, into a wall or a dead end).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pybullet as p

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.grid_search import flat_grid
from sessgan_core.valid_tests import inflate, shortest_paths_from
from sessgan_core.validation import require_non_negative, require_positive
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.robots import Robot
from sessgan_sim.world import CollisionGroup

AGENT_BEHAVIOURS = ('blind', 'cautious')

PASSAGE_SHARE = 3
"""A patrol holding cells of a narrow passage is at least this many times as long."""

PATH_TRIES = 8
"""Random destinations tried per agent before it settles for the best path found."""


class KeepClear(NamedTuple):
    """A disc (metres, map frame) where no patrol starts or ends. On a narrow passage of a
    route, ``passage`` > 0: the passage's cells lie within that many metres of (x, y), and a
    patrol may cross the passage but not run along it."""

    x: float
    y: float
    radius: float
    passage: float = 0.0


@dataclass(frozen=True)
class AgentConfig:
    """Dummy agents' size and motion, in metres and m/s."""

    speed: float = 0.5
    radius: float = 0.2
    height: float = 0.3
    min_start_distance: float = 2.0
    """No agent starts closer than this to the robot's start (centre to centre)."""
    min_patrol_cells: int = 4
    """Shortest patrol path, in cells: an agent that finds none is not placed."""
    behaviour: str = 'blind'
    """'blind' (drive on whatever is ahead) or 'cautious' (wait while something is ahead)."""
    safety_distance: float = 0.5
    """m between a cautious agent's body and whatever makes it wait."""

    def validate(self) -> None:
        for name in ('speed', 'radius', 'height'):
            require_positive(f'agents: {name}', getattr(self, name), InvalidConfigError)
        require_non_negative('agents: min_start_distance', self.min_start_distance,
                             InvalidConfigError, ' m')
        if self.behaviour not in AGENT_BEHAVIOURS:
            raise InvalidConfigError(f'agents: behaviour must be one of {AGENT_BEHAVIOURS}, '
                                     f'got {self.behaviour!r}')
        require_non_negative('agents: safety_distance', self.safety_distance,
                             InvalidConfigError, ' m')
        if self.min_patrol_cells < 1:
            raise InvalidConfigError(f'agents: min_patrol_cells must be >= 1, got '
                                     f'{self.min_patrol_cells}')


class PatrolPath:
    """A polyline travelled back and forth; positions by distance travelled."""

    def __init__(self, points: np.ndarray) -> None:
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if not len(points):
            raise ValueError('a patrol path needs at least one point')
        self.points = points
        steps = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
        self._cumulative = np.concatenate([[0.0], np.cumsum(steps)]).tolist()
        self._corners: list[tuple[float, float]] = [(x, y) for x, y in points.tolist()]
        self.length = self._cumulative[-1]

    def position(self, distance: float) -> tuple[float, float]:
        """Point reached after travelling ``distance`` metres from the first point."""
        if self.length <= 0:
            return self._corners[0]
        along = distance % (2 * self.length)
        if along > self.length:
            along = 2 * self.length - along
        index = min(bisect.bisect_right(self._cumulative, along), len(self._cumulative) - 1)
        start = self._cumulative[index - 1]
        span = self._cumulative[index] - start
        share = (along - start) / span if span > 0 else 0.0
        (x0, y0), (x1, y1) = self._corners[index - 1], self._corners[index]
        return x0 + (x1 - x0) * share, y0 + (y1 - y0) * share

    def positions(self, distances: np.ndarray) -> np.ndarray:
        """(n, 2) points reached after travelling each of ``distances`` metres (position,
        for many distances at once)."""
        distances = np.asarray(distances, dtype=float)
        if self.length <= 0:
            return np.broadcast_to(self.points[0], (len(distances), 2)).copy()
        along = np.mod(distances, 2 * self.length)
        along = np.where(along > self.length, 2 * self.length - along, along)
        return np.stack([np.interp(along, self._cumulative, self.points[:, 0]),
                         np.interp(along, self._cumulative, self.points[:, 1])], axis=-1)


class PatrolSpace:
    """Where the agents of an episode may patrol (the class docstring's rule): the part of
    their patrols that no random draw decides, so patrols for many seeds cost only their
    draws. ``passable_values``: the occupancy values the robot's plane passes;
    ``keep_clear``: where no patrol starts or ends (KeepClear)."""

    def __init__(self, environment: Environment, passable_values: Sequence[int],
                 config: AgentConfig, keep_clear: Sequence[KeepClear] = ()) -> None:
        self.environment, self.config = environment, config
        resolution = environment.resolution
        passable = np.isin(environment.occupancy, passable_values)
        self.free = inflate(passable, config.radius / resolution)
        self.grid = flat_grid(self.free)
        self.rows, self.cols = np.nonzero(self.free)
        centres_x = environment.origin[0] + (self.cols + 0.5) * resolution
        centres_y = environment.origin[1] + (self.rows + 0.5) * resolution
        start: Pose2D = environment.start
        allowed = np.ones(len(self.rows), dtype=bool)
        narrow = np.zeros(len(self.rows), dtype=bool)
        widest = 0.0
        for disc in keep_clear:
            distance = np.hypot(centres_x - disc.x, centres_y - disc.y)
            allowed &= distance >= disc.radius
            if disc.passage > 0.0:
                # Half a cell more: a cell whose centre is that far still reaches into it.
                narrow |= distance < disc.passage + 0.5 * resolution
                widest = max(widest, disc.passage)
        # No patrol turns around inside a passage either: there an agent would block it.
        allowed &= ~narrow
        far = np.hypot(centres_x - start.x, centres_y - start.y) >= config.min_start_distance
        self.spawn_cells = np.flatnonzero(far & allowed)
        self.end_cells = np.flatnonzero(allowed)
        self.narrow = np.zeros(self.free.shape, dtype=bool)
        self.narrow[self.rows[narrow], self.cols[narrow]] = True
        self.crossing_cells = math.ceil(2.0 * widest / resolution) + 1
        """Most cells of narrow passage a patrol may hold: a crossing (the passage is
        narrower than twice its ``passage``), one more for a slant."""

    def patrols(self, count: int, rng: np.random.Generator) -> list[PatrolPath]:
        """The patrols of up to ``count`` agents, drawn from ``rng``: what DummyAgents.spawn
        places (none where no cell is far enough from the start; no agent where no patrol of
        ``min_patrol_cells`` was found: one standing still or shuttling on the spot would
        hold a robot that waits for it until the time limit, as waiting beside an agent never
        counts as stuck)."""
        if not len(self.spawn_cells):
            return []
        rows, cols = self.rows, self.cols
        paths = []
        for _ in range(count):
            first = int(rng.choice(self.spawn_cells))
            origin_cell = (int(rows[first]), int(cols[first]))
            path_to = shortest_paths_from(self.free, origin_cell, self.grid)
            best = [origin_cell]
            for _ in range(PATH_TRIES):
                other = int(rng.choice(self.end_cells))
                path = path_to((int(rows[other]), int(cols[other])))
                if len(path) > len(best) and self.only_crosses(path):
                    best = path
                if len(best) >= self.config.min_patrol_cells:
                    break
            if len(best) >= self.config.min_patrol_cells:
                paths.append(PatrolPath(np.array([self.environment.cell_center(row, col)
                                                  for row, col in best])))
        return paths

    def only_crosses(self, path: Sequence[tuple[int, int]]) -> bool:
        """Whether ``path`` (cells) only crosses the narrow passages, not runs along one,
        and is long beside its cells there: an agent on it is in a passage for at most a
        third of its time, so a robot waiting at the passage gets windows to pass (a 4-cell
        patrol with 2 cells across a passage held a robot beside it until the time limit)."""
        held = sum(bool(self.narrow[cell]) for cell in path)
        return held <= self.crossing_cells and len(path) >= PASSAGE_SHARE * held


class DummyAgents:
    """The agents of one episode."""

    def __init__(self, config: AgentConfig | None = None) -> None:
        self.config = config or AgentConfig()
        self.config.validate()
        self.body_ids: list[int] = []
        self.paths: list[PatrolPath] = []
        self.positions = np.zeros((0, 2))
        self.velocities = np.zeros((0, 2))
        """m/s, each agent's motion over the last ``advance``."""
        self._client = -1
        self._height = 0.0
        self._travelled: list[float] = []
        """Metres each agent has moved along its patrol."""
        self._robot_radius = 0.0
        self._index_of_body: dict[int, int] = {}

    def spawn(self, client: int, environment: Environment, robot: Robot, count: int,
              rng: np.random.Generator,
              keep_clear: Sequence[KeepClear] = ()) -> int:
        """Create up to ``count`` agents; return how many found room.

        ``keep_clear``: where no patrol starts or ends (KeepClear).
        """
        if count < 0:
            raise InvalidConfigError(f'agents: count must be >= 0, got {count}')
        self._client = client
        self._height = robot.traffic_height
        self._robot_radius = robot.footprint_radius
        self.body_ids, self.paths = [], []
        self._index_of_body = {}
        if count == 0:
            self.positions, self.velocities = np.zeros((0, 2)), np.zeros((0, 2))
            return 0
        self.paths = PatrolSpace(environment, robot.passable_values, self.config,
                                 keep_clear).patrols(count, rng)
        if not self.paths:
            self.positions, self.velocities = np.zeros((0, 2)), np.zeros((0, 2))
            return 0
        config = self.config
        shape = p.createCollisionShape(p.GEOM_CYLINDER, radius=config.radius,
                                       height=config.height, physicsClientId=client)
        for path in self.paths:
            x, y = path.points[0]
            body = p.createMultiBody(0.0, shape, basePosition=[x, y, self._height],
                                     physicsClientId=client)
            p.setCollisionFilterGroupMask(
                body, -1, int(CollisionGroup.AGENT),
                int(CollisionGroup.ROBOT | CollisionGroup.RAY), physicsClientId=client)
            self.body_ids.append(body)
        self.positions = np.array([path.position(0.0) for path in self.paths])
        self.velocities = np.zeros((len(self.paths), 2))
        self._travelled = [0.0] * len(self.paths)
        self._index_of_body = {body: index for index, body in enumerate(self.body_ids)}
        return len(self.body_ids)

    @property
    def centre_height(self) -> float:
        """Height (m) of the agents' centres above the ground."""
        return self._height

    def index_of(self, body_id: int) -> int | None:
        """Index of the agent whose pybullet body is ``body_id``; None for any other body."""
        return self._index_of_body.get(body_id)

    def advance(self, dt: float,
                robot_positions: Sequence[tuple[float, float]] = ()) -> None:
        """Move every agent ``dt`` seconds further along its patrol (a cautious agent waits
        while a robot under test at one of ``robot_positions`` or another agent is ahead of
        it; a blind one touching one of those robots turns back)."""
        if not self.body_ids:
            return
        step = self.config.speed * dt
        cautious = self.config.behaviour == 'cautious'
        client, height, travelled = self._client, self._height, self._travelled
        positions, velocities = self.positions, self.velocities
        for index, (body, path) in enumerate(zip(self.body_ids, self.paths, strict=True)):
            x, y = path.position(travelled[index] + step)
            if cautious and self._blocked(index, x, y, robot_positions):
                velocities[index] = 0.0
                continue
            if not cautious and self._pressing(index, x, y, robot_positions):
                # The same point, walked the other way (PatrolPath.position).
                travelled[index] = 2 * path.length - travelled[index] % (2 * path.length)
                x, y = path.position(travelled[index] + step)
            travelled[index] += step
            velocities[index, 0] = (x - positions[index, 0]) / dt
            velocities[index, 1] = (y - positions[index, 1]) / dt
            positions[index, 0] = x
            positions[index, 1] = y
            p.resetBasePositionAndOrientation(body, [x, y, height], [0.0, 0.0, 0.0, 1.0],
                                              physicsClientId=client)

    def _pressing(self, index: int, next_x: float, next_y: float,
                  robot_positions: Sequence[tuple[float, float]]) -> bool:
        """Whether agent ``index`` touches a robot at one of ``robot_positions`` and its move
        to (next_x, next_y) would press into it."""
        x, y = self.positions[index]
        touch = self.config.radius + self._robot_radius  # bodies touching: the contact is made
        for robot_x, robot_y in robot_positions:
            distance = math.hypot(robot_x - x, robot_y - y)
            if distance <= touch and math.hypot(robot_x - next_x, robot_y - next_y) < distance:
                return True
        return False

    def _blocked(self, index: int, next_x: float, next_y: float,
                 robot_positions: Sequence[tuple[float, float]]) -> bool:
        """Whether something stands within the safety distance ahead of agent ``index``
        moving to (next_x, next_y): inside a corridor as wide as both bodies."""
        x, y = self.positions[index]
        dx, dy = next_x - x, next_y - y
        norm = math.hypot(dx, dy)
        if norm == 0.0:
            return False
        dx, dy = dx / norm, dy / norm
        radius = self.config.radius
        others = [(float(ox), float(oy), radius) for other, (ox, oy)
                  in enumerate(self.positions) if other != index]
        others += [(robot_x, robot_y, self._robot_radius) for robot_x, robot_y in robot_positions]
        for ox, oy, other_radius in others:
            ahead = (ox - x) * dx + (oy - y) * dy
            beside = abs((ox - x) * dy - (oy - y) * dx)
            reach = radius + other_radius
            if 0.0 < ahead < reach + self.config.safety_distance and beside < reach:
                return True
        return False
