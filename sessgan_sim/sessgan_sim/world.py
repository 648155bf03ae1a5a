"""The pybullet world of an episode, built from an Environment.

Geometry (all static, z up, the map frame is pybullet's world frame):

* BLOCKED cells (100) become **walls** (tall boxes) or, in scenarios that
  register it (the race track), **out-of-bounds barriers**: low boxes the car
  physically hits. LOW_OBSTACLE cells (50) become short boxes (0.3 m) that ground
  robots hit, and the flyer too when it flies lower than their height; above them it
  passes over. Walls (2 m) are taller than the flyer may climb. The grid's outside
  counts as blocked: a one-cell ring of the blocked kind closes the map.
* Cells of one kind are merged greedily into maximal rectangles, one box per
  rectangle (the 32x32 factory map: 41 boxes for 400 wall cells), and
  neighbouring boxes share a static compound body (up to 16 each: 4 bodies for
  the factory map). Solid boxes keep contacts robust: a car at 12 m/s cannot
  tunnel through a barrier, as it can through a hollow triangle mesh.
* The default lidar casts its rays analytically from the layout's ``heights``
  (sessgan_sim.sensors). The pybullet lidar does not see the boxes either:
  Bullet's ray cast against a box is costly (a convex cast per box the ray
  crosses). It sees a separate, ray-only triangle mesh instead: the vertical
  faces between cells of different heights, merged along grid lines (146 quads
  for the factory map), which casts about three times faster. The mesh has no
  top faces: the scan plane is horizontal.
* A ground slab (a thin box under the map, top at z = 0) is scenery: gravity is
  off and every body rides at a fixed height, so nothing touches it.

Collision groups (:class:`CollisionGroup`) decide who meets whom: the robot
touches obstacles and agents; rays hit the scan surface and agents. A body
whose mask lacks RAY is skipped by ray tests before any geometry is computed
(the robot, the boxes, the ground), which is what keeps them cheap.
"""

from __future__ import annotations

import contextlib
import enum
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np
import pybullet as p

from sessgan_core.environment import Environment
from sessgan_core.scenarios import BLOCKED, LOW_OBSTACLE
from sessgan_core.validation import require_non_negative, require_positive
from sessgan_sim.errors import InvalidConfigError, WorldError


class CollisionGroup(enum.IntFlag):
    """Bullet collision filter bits.

    Two bodies collide when each one's group meets the other's mask. Ray tests
    belong to group RAY, so a body is visible to rays only when its mask holds RAY
    and its group is in the ray's mask (:data:`SCAN_RAY_MASK`).
    """

    RAY = 1
    ROBOT = 2
    OBSTACLE = 4
    AGENT = 8
    SCAN_SURFACE = 16
    GROUND = 32


SCAN_RAY_MASK = int(CollisionGroup.OBSTACLE | CollisionGroup.AGENT | CollisionGroup.SCAN_SURFACE)
"""Mask of lidar rays. Obstacle boxes are hit only in a world without a scan surface, the
only one where their own mask holds RAY (:attr:`WorldStyle.scan_surface`)."""

ROBOT_MASK = int(CollisionGroup.OBSTACLE | CollisionGroup.AGENT | CollisionGroup.ROBOT)
"""Mask of the robot under test: it touches obstacles, agents and the other robots under
test of a fleet, nothing else."""

GROUND_THICKNESS = 0.1
"""m, thickness of the ground slab under the map."""

BOXES_PER_BODY = 16
"""Boxes per static body (pybullet's limit for a compound shape). Fewer bodies make every
query cheaper: each one a ray crosses costs time even when the ray ignores it."""

MAX_QUADS_PER_MESH = 30000
"""pybullet caps a mesh at 131072 vertices; larger scan surfaces are split into several."""


class ObstacleKind(enum.StrEnum):
    """What a static obstacle box stands for."""

    WALL = 'wall'
    OUT_OF_BOUNDS = 'out_of_bounds'
    LOW_OBSTACLE = 'low_obstacle'


BLOCKED_CELL_KINDS: dict[str, ObstacleKind] = {}
"""Scenario name -> kind of its BLOCKED cells; scenarios not listed get walls."""


def register_blocked_kind(scenario_name: str, kind: ObstacleKind) -> None:
    """Declare what the BLOCKED cells of a scenario are (walls unless registered)."""
    BLOCKED_CELL_KINDS[scenario_name] = ObstacleKind(kind)


def blocked_kind(scenario_name: str) -> ObstacleKind:
    """Kind of the BLOCKED cells of a scenario."""
    return BLOCKED_CELL_KINDS.get(scenario_name, ObstacleKind.WALL)


register_blocked_kind('racetrack', ObstacleKind.OUT_OF_BOUNDS)


@dataclass(frozen=True)
class WorldStyle:
    """Physical dimensions of the static world, in metres."""

    wall_height: float = 2.0
    """Walls rise above every robot, the flyer at its highest altitude included (an episode
    refuses a flyer whose ``max_altitude + height`` reaches it)."""
    barrier_height: float = 0.3
    """Out-of-bounds barriers: a kerb-high wall just above the car's scan plane (0.2 m), so
    its lidar sees the track edge and its body hits the barrier."""
    low_obstacle_height: float = 0.3
    """Seen and hit by ground robots (scan plane 0.2 m) and by the flyer below this altitude;
    flown over above it."""
    merge_obstacles: bool = True
    """Merge cells into maximal rectangles, several per body; False builds one box body per
    cell (the benchmark's baseline)."""
    scan_surface: bool = True
    """Let the lidar see the ray-only triangle surface instead of the boxes (cheaper rays);
    False casts the rays against the boxes (the benchmark's baseline)."""
    friction: float = 0.5
    """Lateral friction coefficient of the obstacles."""

    def height_of(self, kind: ObstacleKind) -> float:
        """Height in metres of an obstacle of this kind."""
        return {
            ObstacleKind.WALL: self.wall_height,
            ObstacleKind.OUT_OF_BOUNDS: self.barrier_height,
            ObstacleKind.LOW_OBSTACLE: self.low_obstacle_height,
        }[kind]

    def validate(self) -> None:
        """Raise InvalidConfigError unless every dimension is positive and finite."""
        for name in ('wall_height', 'barrier_height', 'low_obstacle_height'):
            require_positive(f'world style: {name}', getattr(self, name), InvalidConfigError,
                             ' m')
        require_non_negative('world style: friction', self.friction, InvalidConfigError)


@dataclass(frozen=True)
class ObstacleBox:
    """One static box of the world: a merged rectangle of cells, or one cell."""

    body_id: int
    """The static body holding the box; up to :data:`BOXES_PER_BODY` boxes share one."""
    kind: ObstacleKind
    x_min: float
    y_min: float
    x_max: float
    y_max: float
    height: float


@dataclass
class WorldLayout:
    """What :meth:`World.build` created, for sensors, agents and metrics."""

    environment_id: str
    obstacles: tuple[ObstacleBox, ...]
    ground_id: int
    scan_surface_ids: tuple[int, ...]
    """Ray-only mesh bodies; empty without a scan surface (rays hit the boxes)."""
    heights: np.ndarray
    """float array (height, width): obstacle height of each cell in metres (0 = free)."""
    body_ids: np.ndarray
    """int array (n,) of the static obstacle bodies."""
    body_bounds: np.ndarray
    """float array (n, 4): x_min, y_min, x_max, y_max of each body's boxes together."""
    body_kinds: tuple[ObstacleKind, ...]
    """Kind of each body's boxes (a body holds boxes of one kind)."""
    resolution: float
    """m, side of a cell of ``heights``."""
    origin: tuple[float, float]
    """(x, y) in m of the corner of cell (0, 0) of ``heights`` (its lowest x and y)."""
    border_height: float
    """m, height of the one-cell ring closing the map (the blocked cells' kind); beyond the
    ring lies nothing (height 0)."""
    _bounds_list: list[tuple[int, list[float]]] | None = field(default=None, repr=False)

    def kind_of(self, body_id: int) -> ObstacleKind | None:
        """Kind of a static obstacle body, None for any other body."""
        for body, kind in zip(self.body_ids.tolist(), self.body_kinds, strict=True):
            if body == body_id:
                return kind
        return None

    def obstacles_near(self, x: float, y: float, reach: float) -> list[int]:
        """Ids of the obstacle bodies with a box possibly within ``reach`` metres of (x, y)
        (their bounds are; the boxes themselves may lie farther)."""
        if self._bounds_list is None:
            self._bounds_list = list(zip(self.body_ids.tolist(), self.body_bounds.tolist(),
                                         strict=True))
        near = []
        squared = reach * reach
        # A plain loop: a merged map has a handful of bodies, too few for numpy to pay off.
        for body, (x_min, y_min, x_max, y_max) in self._bounds_list:
            dx = x_min - x if x < x_min else x - x_max if x > x_max else 0.0
            dy = y_min - y if y < y_min else y - y_max if y > y_max else 0.0
            if dx * dx + dy * dy <= squared:
                near.append(body)
        return near


Rectangle = tuple[int, int, int, int]
"""Cells (row, col, rows, cols): the lowest row and column and the extent."""


def merge_cells(mask: np.ndarray) -> list[Rectangle]:
    """Cover the True cells of ``mask`` with disjoint rectangles, greedily.

    Row-major scan: from each uncovered cell, extend right as far as possible, then
    up while the whole span stays uncovered. Exact cover, few rectangles for the
    straight walls of maps.
    """
    remaining = np.asarray(mask, dtype=bool).tolist()
    height = len(remaining)
    width = len(remaining[0]) if height else 0
    rectangles: list[Rectangle] = []
    for row in range(height):
        line = remaining[row]
        col = 0
        while col < width:
            if not line[col]:
                col += 1
                continue
            end = col + 1
            while end < width and line[end]:
                end += 1
            top = row + 1
            while top < height and all(remaining[top][col:end]):
                top += 1
            for covered in range(row, top):
                remaining[covered][col:end] = [False] * (end - col)
            rectangles.append((row, col, top - row, end - col))
            col = end
    return rectangles


def cell_rectangles(mask: np.ndarray) -> list[Rectangle]:
    """One rectangle per True cell (the unmerged baseline)."""
    return [(int(row), int(col), 1, 1) for row, col in np.argwhere(mask)]


def group_rectangles(rectangles: list[Rectangle], size: int) -> list[list[Rectangle]]:
    """Split rectangles into spatially compact groups of at most ``size`` (a k-d split at
    the median centre along the wider axis), so each group's bounds stay small."""
    if len(rectangles) <= size:
        return [rectangles] if rectangles else []
    rows = [row + rows / 2 for row, _, rows, _ in rectangles]
    cols = [col + cols / 2 for _, col, _, cols in rectangles]
    axis = rows if max(rows) - min(rows) >= max(cols) - min(cols) else cols
    order = sorted(range(len(rectangles)), key=lambda index: (axis[index], index))
    half = len(order) // 2
    return (group_rectangles([rectangles[index] for index in order[:half]], size)
            + group_rectangles([rectangles[index] for index in order[half:]], size))


Quad = tuple[tuple[float, float], tuple[float, float], float, float]
"""A vertical face: two ground points (x, y) and the z range (bottom, top)."""


def _face_runs(low: list[float], high: list[float]) -> Iterator[tuple[int, int, float, float]]:
    """Runs (first, end, bottom, top) of consecutive faces with the same z range."""
    start = 0
    count = len(low)
    while start < count:
        bottom, top = low[start], high[start]
        if bottom == top:
            start += 1
            continue
        end = start + 1
        while end < count and low[end] == bottom and high[end] == top:
            end += 1
        yield start, end, bottom, top
        start = end


def vertical_faces(heights: np.ndarray, resolution: float,
                   origin: tuple[float, float]) -> list[Quad]:
    """The vertical faces between cells of different heights, merged along grid lines.

    ``heights`` is (rows, cols) in OccupancyGrid order with cell (0, 0)'s corner at
    ``origin``; the outside counts as height 0. A face between heights a and b spans z
    from min(a, b) to max(a, b).
    """
    padded = np.pad(np.asarray(heights, dtype=float), 1)
    ox, oy = origin
    quads: list[Quad] = []
    # Faces normal to x, on the line x = ox + line * resolution, running along rows.
    west, east = padded[1:-1, :-1], padded[1:-1, 1:]
    low_x, high_x = np.minimum(west, east).T.tolist(), np.maximum(west, east).T.tolist()
    for line, (low, high) in enumerate(zip(low_x, high_x, strict=True)):
        x = ox + line * resolution
        for first, end, bottom, top in _face_runs(low, high):
            quads.append(((x, oy + first * resolution), (x, oy + end * resolution), bottom, top))
    # Faces normal to y, on the line y = oy + line * resolution, running along columns.
    south, north = padded[:-1, 1:-1], padded[1:, 1:-1]
    low_y, high_y = np.minimum(south, north).tolist(), np.maximum(south, north).tolist()
    for line, (low, high) in enumerate(zip(low_y, high_y, strict=True)):
        y = oy + line * resolution
        for first, end, bottom, top in _face_runs(low, high):
            quads.append(((ox + first * resolution, y), (ox + end * resolution, y), bottom, top))
    return quads


def write_obj(quads: list[Quad], path: str) -> None:
    """Write quads as a Wavefront OBJ triangle mesh (two triangles per quad)."""
    lines = []
    for (x0, y0), (x1, y1), bottom, top in quads:
        lines += [f'v {x0!r} {y0!r} {bottom!r}', f'v {x1!r} {y1!r} {bottom!r}',
                  f'v {x1!r} {y1!r} {top!r}', f'v {x0!r} {y0!r} {top!r}']
    for index in range(len(quads)):
        first = 4 * index + 1
        lines += [f'f {first} {first + 1} {first + 2}', f'f {first} {first + 2} {first + 3}']
    with open(path, 'w', encoding='ascii') as stream:
        stream.write('\n'.join(lines))
        stream.write('\n')


class World:
    """A pybullet physics client (DIRECT, never a GUI) and the world built in it.

    Use as a context manager, or call :meth:`open` and :meth:`close`. Each
    :meth:`build` resets the simulation, so one World serves many episodes
    without leaking bodies, shapes or time.
    """

    def __init__(self) -> None:
        self._client: int | None = None
        self._layout: WorldLayout | None = None
        self._mesh_dir = ''

    def open(self) -> World:
        """Connect a DIRECT pybullet client (no-op when already open)."""
        if self._client is None:
            client = p.connect(p.DIRECT)
            if client < 0:
                raise WorldError('pybullet could not open a DIRECT physics client')
            self._client = client
            self._mesh_dir = tempfile.mkdtemp(prefix='sessgan_sim_world_')
        return self

    def close(self) -> None:
        """Disconnect the client; the World may be opened again."""
        if self._client is not None:
            try:
                p.disconnect(physicsClientId=self._client)
            finally:
                self._client = None
                self._layout = None
                shutil.rmtree(self._mesh_dir, ignore_errors=True)

    @property
    def is_open(self) -> bool:
        return self._client is not None

    def __enter__(self) -> World:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def __del__(self) -> None:
        # Last resort: a client left open would keep its memory until the process ends.
        if getattr(self, '_client', None) is not None:
            # At interpreter shutdown pybullet or shutil may already be gone.
            with contextlib.suppress(Exception):
                self.close()

    @property
    def client(self) -> int:
        """The pybullet physics client id; WorldError when closed."""
        if self._client is None:
            raise WorldError('the world is closed; open() it or use it as a context manager')
        return self._client

    @property
    def layout(self) -> WorldLayout:
        """The layout of the last build; WorldError before any build."""
        if self._layout is None:
            raise WorldError('the world has not been built; call build(environment) first')
        return self._layout

    def body_count(self) -> int:
        """Number of bodies in the simulation."""
        return p.getNumBodies(physicsClientId=self.client)

    def build(self, environment: Environment, physics_timestep: float,
              style: WorldStyle | None = None) -> WorldLayout:
        """Reset the simulation and build the static world of ``environment``.

        ``environment`` must be valid (:meth:`Environment.validate`); the physics step is
        ``physics_timestep`` seconds.
        """
        style = style or WorldStyle()
        style.validate()
        require_positive('physics timestep', physics_timestep, InvalidConfigError, ' s')
        client = self.client
        p.resetSimulation(physicsClientId=client)
        p.setGravity(0.0, 0.0, 0.0, physicsClientId=client)
        p.setPhysicsEngineParameter(fixedTimeStep=physics_timestep, numSubSteps=0,
                                    numSolverIterations=10, deterministicOverlappingPairs=1,
                                    enableFileCaching=0, physicsClientId=client)

        resolution = float(environment.resolution)
        # The ring of blocked cells closes the map: the outside counts as blocked.
        origin = (float(environment.origin[0]) - resolution,
                  float(environment.origin[1]) - resolution)
        occupancy = np.pad(np.asarray(environment.occupancy), 1, constant_values=BLOCKED)
        kind_masks = [(blocked_kind(environment.scenario), occupancy == BLOCKED),
                      (ObstacleKind.LOW_OBSTACLE, occupancy == LOW_OBSTACLE)]
        heights = np.zeros(occupancy.shape, dtype=float)
        for kind, mask in kind_masks:
            heights[mask] = style.height_of(kind)

        height, width = occupancy.shape
        half_ground = [width * resolution / 2, height * resolution / 2, GROUND_THICKNESS / 2]
        ground_shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_ground,
                                              physicsClientId=client)
        ground_id = p.createMultiBody(
            0.0, ground_shape, basePosition=[origin[0] + half_ground[0],
                                             origin[1] + half_ground[1], -half_ground[2]],
            physicsClientId=client)
        p.setCollisionFilterGroupMask(ground_id, -1, int(CollisionGroup.GROUND), 0,
                                      physicsClientId=client)

        obstacle_mask = int(CollisionGroup.ROBOT)
        if not style.scan_surface:
            obstacle_mask |= int(CollisionGroup.RAY)
        obstacles: list[ObstacleBox] = []
        body_ids: list[int] = []
        body_bounds: list[list[float]] = []
        body_kinds: list[ObstacleKind] = []
        for kind, mask in kind_masks:
            box_height = style.height_of(kind)
            if style.merge_obstacles:
                groups = group_rectangles(merge_cells(mask), BOXES_PER_BODY)
            else:
                groups = [[cell] for cell in cell_rectangles(mask)]
            for group in groups:
                boxes = [(origin[0] + col * resolution, origin[1] + row * resolution,
                          origin[0] + (col + cols) * resolution,
                          origin[1] + (row + rows) * resolution)
                         for row, col, rows, cols in group]
                shape = p.createCollisionShapeArray(
                    [p.GEOM_BOX] * len(boxes),
                    halfExtents=[[(x1 - x0) / 2, (y1 - y0) / 2, box_height / 2]
                                 for x0, y0, x1, y1 in boxes],
                    collisionFramePositions=[[(x0 + x1) / 2, (y0 + y1) / 2, box_height / 2]
                                             for x0, y0, x1, y1 in boxes],
                    physicsClientId=client)
                if shape < 0:
                    raise WorldError(f'pybullet could not create the obstacles of '
                                     f'environment {environment.id!r}')
                body = p.createMultiBody(0.0, shape, physicsClientId=client)
                p.setCollisionFilterGroupMask(body, -1, int(CollisionGroup.OBSTACLE),
                                              obstacle_mask, physicsClientId=client)
                p.changeDynamics(body, -1, lateralFriction=style.friction, restitution=0.0,
                                 physicsClientId=client)
                obstacles += [ObstacleBox(body, kind, *box, box_height) for box in boxes]
                corners = np.array(boxes)
                body_ids.append(body)
                body_bounds.append([*corners[:, :2].min(axis=0), *corners[:, 2:].max(axis=0)])
                body_kinds.append(kind)

        scan_ids: list[int] = []
        if style.scan_surface:
            quads = vertical_faces(heights, resolution, origin)
            for first in range(0, len(quads), MAX_QUADS_PER_MESH):
                # pybullet 3.2.7 keeps a reference to every vertex list passed to
                # createCollisionShape(vertices=...), leaking them each build; a mesh
                # loaded from a file (with file caching off) leaks nothing.
                mesh_path = os.path.join(self._mesh_dir, f'scan_surface_{first}.obj')
                write_obj(quads[first:first + MAX_QUADS_PER_MESH], mesh_path)
                try:
                    shape = p.createCollisionShape(p.GEOM_MESH, fileName=mesh_path,
                                                   flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                                                   physicsClientId=client)
                    if shape < 0:
                        raise WorldError(f'pybullet could not create the scan surface of '
                                         f'environment {environment.id!r}')
                    # The body reads the file too (for its visual shape).
                    body = p.createMultiBody(0.0, shape, physicsClientId=client)
                finally:
                    os.remove(mesh_path)
                p.setCollisionFilterGroupMask(body, -1, int(CollisionGroup.SCAN_SURFACE),
                                              int(CollisionGroup.RAY), physicsClientId=client)
                scan_ids.append(body)

        self._layout = WorldLayout(
            environment_id=environment.id,
            obstacles=tuple(obstacles),
            ground_id=ground_id,
            scan_surface_ids=tuple(scan_ids),
            heights=heights[1:-1, 1:-1].copy(),
            body_ids=np.array(body_ids, dtype=np.int64),
            body_bounds=np.array(body_bounds, dtype=float).reshape(-1, 4),
            body_kinds=tuple(body_kinds),
            resolution=resolution,
            origin=(float(environment.origin[0]), float(environment.origin[1])),
            border_height=style.height_of(kind_masks[0][0]),
        )
        return self._layout
