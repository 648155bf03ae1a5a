"""Sensors of the robot under test: a planar lidar, odometry, contact, clearance, and the
flyer's downward range sensor (:class:`RangeFinder`).

The lidar casts its beams in the robot's body frame, from the body's centre at
the robot's sensor height (frame ``base_scan`` sits on ``base_footprint``'s z
axis). What it sees follows from that height:

* ground robots (scan plane 0.2 m) see walls, out-of-bounds barriers, low
  obstacles (0.3 m) and ground agents;
* the flyer's scan plane moves with it (half its body height above its altitude):
  cruising at its traffic altitude (plane at 1.0 m) it sees walls and other flyers but
  not low obstacles, which lie below the plane as they would for a real planar lidar on
  a drone; flying lower than a low obstacle's height (0.3 m) it sees them too. They
  remain on the ``map`` topic (value 50) for controllers that must consider them, and
  the flyer's downward range sensor (:class:`RangeFinder`) reads them from above.

In general a cell is opaque to the scan when its obstacle is taller than the scan
plane, and an agent (a vertical cylinder) when the plane cuts it; both are decided at
every scan from the plane's height then. Two casters
compute the same ranges (:class:`RayCaster`): the default casts analytically in
numpy against the faces where opacity changes and against the agents' circles
(:class:`PlanarRayCaster`); the baseline casts with ``p.rayTestBatch`` against the
world's ray-only scan surface and the agents' bodies. They agree to floating-
point precision on walls except on a beam that passes a wall's corner closer than
Bullet's edge tolerance (1e-4 of the face's length; under 0.1% of the beams), which
Bullet counts as a hit; on agents Bullet's convex ray cast against a cylinder is
off by about 0.1 mm, up to a centimetre at grazing incidence. The analytic caster
is the exact one.

Readings follow REP 117: a beam with no return within ``range_max`` reads +inf,
a return closer than ``range_min`` reads -inf; other returns get Gaussian noise
of ``noise_std`` metres, drawn from the episode's seeded generator, and are kept
within [range_min, range_max].
"""

from __future__ import annotations

import bisect
import enum
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pybullet as p

from sessgan_core.environment import Pose2D
from sessgan_core.validation import require_non_negative, require_positive
from sessgan_sim.agents import DummyAgents
from sessgan_sim.errors import InvalidConfigError, SessganSimError
from sessgan_sim.robots import Robot
from sessgan_sim.world import SCAN_RAY_MASK, WorldLayout

_HIT_FRACTION = operator.itemgetter(2)

CONTACT_TOLERANCE = 1e-3
"""m: contact points closer than this (or penetrating) count as touching."""

TWO_PI = 2 * math.pi

GRAZING_TOLERANCE = 1e-6
"""Beams (a fraction of the angle between two beams): how far past its ends the analytic
lidar still lets a face meet a beam. Bullet's triangle test allows 1e-4 of the face's length."""


class RayCaster(enum.StrEnum):
    """How the lidar casts its beams."""

    ANALYTIC = 'analytic'
    """Exact ray casting in numpy against the grid's faces and the agents' circles."""
    PYBULLET = 'pybullet'
    """One ``p.rayTestBatch`` against the scan surface and the agents' bodies (the baseline,
    several times slower)."""


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
    caster: RayCaster = RayCaster.ANALYTIC
    """How the beams are cast; both give the same ranges (see the module's docstring)."""

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable parameter."""
        if not (isinstance(self.beams, int) and 1 <= self.beams <= 16384):
            raise InvalidConfigError(f'lidar: beams must be an integer in 1..16384, '
                                     f'got {self.beams!r}')
        if not (math.isfinite(self.field_of_view) and 0 < self.field_of_view <= 2 * math.pi):
            raise InvalidConfigError(f'lidar: field_of_view must be in (0, 2*pi] rad, got '
                                     f'{self.field_of_view}')
        require_non_negative('lidar: range_min', self.range_min, InvalidConfigError, ' m')
        if not (math.isfinite(self.range_max) and self.range_max > self.range_min):
            raise InvalidConfigError(f'lidar: range_max must exceed range_min, got '
                                     f'{self.range_max} <= {self.range_min}')
        require_positive('lidar: rate_hz', self.rate_hz, InvalidConfigError)
        require_non_negative('lidar: noise_std', self.noise_std, InvalidConfigError, ' m')
        if self.caster not in tuple(RayCaster):
            raise InvalidConfigError(f'lidar: caster must be one of '
                                     f'{[caster.value for caster in RayCaster]}, '
                                     f'got {self.caster!r}')

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


@dataclass(frozen=True)
class GridFaces:
    """The faces a planar scan can hit in a grid: axis-aligned segments between an opaque and
    a transparent cell, merged along grid lines while the opaque side stays the same.

    Each segment is oriented: seen from its transparent side, ``ends[0]`` comes before
    ``ends[1]`` turning counter-clockwise.
    """

    ends: np.ndarray
    """float (2, S, 2), m: the (x, y) of every segment's first ends, then of its second ends."""
    normal_axis: np.ndarray
    """int (S,): 0 for a segment on a line x = const, 1 for one on a line y = const."""

    def __len__(self) -> int:
        return self.ends.shape[1]

    def reversed(self) -> GridFaces:
        """The segments oriented as seen from their opaque side (ends swapped)."""
        return GridFaces(self.ends[::-1].copy(), self.normal_axis)


def _runs(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Runs of equal non-zero values along each row of ``codes`` (lines x positions): the
    line, first position, end position (exclusive) and value of each run."""
    lines, length = codes.shape
    # A zero after every line keeps a run from spilling over into the next line.
    padded = np.zeros((lines, length + 1), dtype=np.int8)
    padded[:, :length] = codes
    flat = padded.ravel()
    boundaries = np.append(np.flatnonzero(np.diff(flat, prepend=np.int8(0))), flat.size)
    starts, ends = boundaries[:-1], boundaries[1:]
    values = flat[starts]
    nonzero = values != 0
    starts, ends, values = starts[nonzero], ends[nonzero], values[nonzero]
    line, first = np.divmod(starts, length + 1)
    return line, first, first + (ends - starts), values


def grid_faces(opaque: np.ndarray, resolution: float, origin: tuple[float, float]) -> GridFaces:
    """The faces of the True cells of ``opaque`` (rows, cols; OccupancyGrid order, cell (0, 0)'s
    corner at ``origin`` m, cells ``resolution`` m wide); the outside is transparent.

    Lines lie at ``origin + line * resolution`` as in :func:`sessgan_sim.world.vertical_faces`:
    the segments are the scan surface's quads that span the scan height.
    """
    grid = np.asarray(opaque, dtype=np.int8)
    ox, oy = float(origin[0]), float(origin[1])
    # Lines x = ox + line * resolution: +1 where the opaque cell lies east of the line.
    across_x = np.pad(grid, ((0, 0), (1, 1)))
    line, first, end, facing = _runs((across_x[:, 1:] - across_x[:, :-1]).T)
    x = ox + line * resolution
    low, high = oy + first * resolution, oy + end * resolution
    east = facing > 0
    # Seen from the west, a face turns counter-clockwise from its low end to its high end.
    ends_x = np.stack((np.stack((x, np.where(east, low, high)), axis=-1),
                       np.stack((x, np.where(east, high, low)), axis=-1)))
    # Lines y = oy + line * resolution: +1 where the opaque cell lies north of the line.
    across_y = np.pad(grid, ((1, 1), (0, 0)))
    line, first, end, facing = _runs(across_y[1:, :] - across_y[:-1, :])
    y = oy + line * resolution
    low, high = ox + first * resolution, ox + end * resolution
    north = facing > 0
    # Seen from the south, a face turns counter-clockwise from its high end to its low end.
    ends_y = np.stack((np.stack((np.where(north, high, low), y), axis=-1),
                       np.stack((np.where(north, low, high), y), axis=-1)))
    return GridFaces(
        np.concatenate((ends_x, ends_y), axis=1).reshape(2, -1, 2),
        np.concatenate((np.zeros(ends_x.shape[1], dtype=np.intp),
                        np.ones(ends_y.shape[1], dtype=np.intp))))


class _FaceSet(NamedTuple):
    """Faces laid out for casting."""

    ends: np.ndarray
    """float (4, S), m: rows x and y of the first ends, x and y of the second ends."""
    inverse_length: np.ndarray
    """float (S,), 1/m."""
    buffer_start: np.ndarray
    """int (S,): where the caster's buffer of nearest faces holds the face's axis."""


class PlanarRayCaster:
    """Exact ray casting in a horizontal plane for a fixed fan of beams: the distance from a
    viewpoint to the first opaque cell of a grid, or to the first of a few circles.

    A face (:class:`GridFaces`) covers the beams between the bearings of its ends; a beam
    meets it at ``|normal offset| / |direction component along the normal|``. A ray from a
    transparent cell meets a face seen from its transparent side before any other (it must
    enter an opaque cell before it can leave one), so only those faces count; from inside
    an opaque cell (a robot deep in a wall) only those seen from their opaque side count,
    which is where Bullet's two-sided triangles report the first hit too. A circle is cut
    analytically; one around the viewpoint is not seen (as in Bullet).

    Bearings are measured in beam units from a reference that puts the bearings no beam
    looks along on either side of 0 = 2 pi: a span of bearings that wraps around there
    covers the beams from its first one to the fan's end, then from beam 0. Such a span
    is kept contiguous in an index range twice the fan's length, folded afterwards.
    """

    def __init__(self, opaque: np.ndarray, resolution: float, origin: tuple[float, float],
                 info: LidarInfo) -> None:
        """``opaque``: bool (rows, cols) grid, cell (0, 0)'s corner at ``origin`` (m), cells
        ``resolution`` m wide; nothing outside it is opaque. ``info``: the beams."""
        # Nested lists: one cell's lookup per scan is faster in plain Python.
        self._opaque = np.asarray(opaque, dtype=bool).tolist()
        self._rows = len(self._opaque)
        self._cols = len(self._opaque[0]) if self._rows else 0
        self._resolution = float(resolution)
        self._origin = (float(origin[0]), float(origin[1]))
        self._beams = beams = info.beams
        self._range = float(info.range_max)
        self.faces = grid_faces(opaque, resolution, origin)
        self._outside = self._face_set(self.faces)
        self._inside = self._face_set(self.faces.reversed())
        angles = info.angles()
        # Rows x and y of the beams' body-frame directions, and of those directions turned
        # a quarter turn: turning by yaw is directions * cos(yaw) + normals * sin(yaw).
        self._directions = np.stack((np.cos(angles), np.sin(angles)))
        self._normals = np.stack((-self._directions[1], self._directions[0]))
        # rad between the reference bearing and beam 0, and between the last beam and 2 pi.
        span = info.angle_increment * (beams - 1)
        self._margin = (TWO_PI - span) / 2
        self._angle_min = info.angle_min
        self._per_radian = 1.0 / info.angle_increment if beams > 1 else 1.0
        self._full_turn = math.isclose(self._margin * self._per_radian, 0.5)
        # Buffers and views reused by every scan: small arrays cost more to set up than to
        # fill. The nearest faces' buffer: per axis (row), the extended beam indices.
        self._viewpoint = np.empty((4, 1))
        self._nearest = np.empty((2, 2 * beams))
        self._nearest_flat = self._nearest.reshape(-1)
        self._nearest_first, self._nearest_wrapped = (self._nearest[:, :beams],
                                                      self._nearest[:, beams:])

    def _face_set(self, faces: GridFaces) -> _FaceSet:
        first, second = faces.ends
        length = np.abs(second - first).sum(axis=1)
        return _FaceSet(np.concatenate((first.T, second.T)), 1.0 / length,
                        faces.normal_axis * (2 * self._beams))

    def cast(self, x: float, y: float, yaw: float, circles: np.ndarray | None = None,
             radius: float = 0.0,
             more_circles: Sequence[tuple[float, float, float]] = ()) -> np.ndarray:
        """Distance in m along every beam from (x, y), the beams turned by ``yaw`` rad, to the
        first face or circle (``circles``: float (n, 2) centres, all ``radius`` m;
        ``more_circles``: (x, y, radius) each, e.g. a fleet's other robots); inf where
        nothing lies within range_max. Hits beyond range_max may read inf or their distance.
        """
        reference = yaw + self._angle_min - self._margin
        directions = self._directions * math.cos(yaw)
        directions += self._normals * math.sin(yaw)
        self._find_nearest_offsets(x, y, reference)
        folded = np.minimum(self._nearest_first, self._nearest_wrapped)
        # Per beam and axis, the nearest face's normal offset over the beam's direction
        # component along that axis. A zero component (a beam exactly along the other axis)
        # meets no face normal to it: inf / 0 stays inf.
        folded /= np.abs(directions)
        ranges = np.minimum(folded[0], folded[1])
        if circles is not None:
            for circle_x, circle_y in circles.tolist():
                self._cut_circle(circle_x - x, circle_y - y, radius, reference, directions,
                                 ranges)
        for circle_x, circle_y, circle_radius in more_circles:
            self._cut_circle(circle_x - x, circle_y - y, circle_radius, reference, directions,
                             ranges)
        return ranges

    def _is_opaque(self, x: float, y: float) -> bool:
        col = math.floor((x - self._origin[0]) / self._resolution)
        row = math.floor((y - self._origin[1]) / self._resolution)
        return 0 <= row < self._rows and 0 <= col < self._cols and self._opaque[row][col]

    def _spans(self, bearings: np.ndarray, reference: float) -> tuple[np.ndarray, np.ndarray]:
        """First extended beam index and count of the beams between the bearings (rad) of
        row 0 and those of row 1 (counter-clockwise, less than a half turn apart)."""
        positions = bearings - reference
        positions %= TWO_PI
        positions -= self._margin
        positions *= self._per_radian
        start, stop = positions
        # A beam that passes a face's end within rounding error (as one from a cell's centre
        # at 45 degrees passes the grid's corners) meets it, at the corner: widen each span
        # by GRAZING_TOLERANCE beams, under a micrometre at range_max.
        first = np.ceil(start - GRAZING_TOLERANCE)
        end = np.floor(stop + GRAZING_TOLERANCE)
        end += 1.0
        if not self._full_turn:
            # Positions beyond the fan's ends name no beam. A full turn needs no clipping:
            # its positions lie in [-1/2, beams - 1/2), widened spans rounding inside it.
            beams = float(self._beams)
            np.minimum(np.maximum(first, 0.0, out=first), beams, out=first)
            np.minimum(np.maximum(end, 0.0, out=end), beams, out=end)
        # first <= end unless the span wraps around, when it runs on past the fan's end.
        counts = end - first
        np.add(counts, self._beams, out=counts, where=stop < start)
        return first.astype(np.intp), counts.astype(np.intp)

    def _find_nearest_offsets(self, x: float, y: float, reference: float) -> None:
        """Fill the buffer of nearest faces (float (2, 2 * beams)): per extended beam index,
        the smallest normal offset (m) of the faces on lines x = const it meets (row 0) and of
        those on y = const (row 1); inf for none."""
        faces = self._inside if self._is_opaque(x, y) else self._outside
        viewpoint = self._viewpoint
        viewpoint[:, 0] = (x, y, x, y)
        relative = faces.ends - viewpoint
        first_x, first_y, second_x, second_y = relative
        # The cross product of the ends is the normal offset times the face's length, and
        # positive for a face seen from the front.
        offset = first_x * second_y
        offset -= first_y * second_x
        offset *= faces.inverse_length
        kept = np.flatnonzero((offset > 0.0) & (offset < self._range))
        relative = relative.take(kept, axis=1)
        bearings = np.arctan2(relative[1::2], relative[0::2])
        start, counts = self._spans(bearings, reference)
        start += faces.buffer_start[kept]
        ends = np.cumsum(counts)
        index = np.arange(ends[-1] if len(ends) else 0)
        start -= ends
        start += counts
        index += np.repeat(start, counts)
        nearest = self._nearest_flat
        nearest.fill(math.inf)
        np.minimum.at(nearest, index, np.repeat(offset[kept], counts))

    def _cut_circle(self, dx: float, dy: float, radius: float, reference: float,
                    directions: np.ndarray, ranges: np.ndarray) -> None:
        """Lower ``ranges`` (m, per beam) to the circle of ``radius`` m centred (dx, dy) m
        from the viewpoint, where the beams (``directions``, float (2, beams)) meet it."""
        squared = dx * dx + dy * dy
        reach = self._range + radius
        if not radius * radius < squared < reach * reach:
            return
        bearing = math.atan2(dy, dx)
        half = math.asin(radius / math.sqrt(squared))
        beams, margin, per_radian = self._beams, self._margin, self._per_radian
        start = ((bearing - half - reference) % TWO_PI - margin) * per_radian
        stop = ((bearing + half - reference) % TWO_PI - margin) * per_radian
        first = min(max(math.ceil(start), 0), beams)
        end = min(max(math.floor(stop) + 1, 0), beams)
        # A span that wraps around covers the fan's end, then its start.
        pieces = ([slice(first, beams), slice(0, end)] if stop < start
                  else [slice(first, end)])
        for covered in pieces:
            if covered.start >= covered.stop:
                continue
            along = directions[0, covered] * dx
            along += directions[1, covered] * dy
            discriminant = along * along
            discriminant -= squared - radius * radius
            # Rounding may leave a beam at the edge of the span just outside: it grazes.
            np.maximum(discriminant, 0.0, out=discriminant)
            along -= np.sqrt(discriminant, out=discriminant)
            np.minimum(ranges[covered], along, out=ranges[covered])


class Lidar:
    """Casts the beams of one scan against the world; one instance per episode."""

    def __init__(self, config: LidarConfig, rng: np.random.Generator) -> None:
        config.validate()
        self.config = config
        self.info = config.info
        self.caster = RayCaster(config.caster)
        self._rng = rng
        self._client = -1
        self._robot: Robot | None = None
        self._agents: DummyAgents | None = None
        self._fleet: list[Robot] = []
        self._planar: PlanarRayCaster | None = None
        self._casters: dict[int, PlanarRayCaster] = {}
        self._levels: list[float] = []
        self._padded_heights = np.zeros((0, 0))
        self._padded_origin = (0.0, 0.0)
        self._resolution = 1.0
        self._starts: list[list[float]] = []
        self._ends: list[list[float]] = []

    def attach(self, client: int, robot: Robot, layout: WorldLayout,
               agents: DummyAgents | None = None, fleet: Sequence[Robot] = ()) -> None:
        """Mount the lidar on ``robot``, spawned in ``layout``'s world (with ``agents`` and
        the other robots under test of a ``fleet``, when they are to be seen): beams start
        at its centre at its sensor height and are cast in its body frame. The planar caster
        sees another robot as the circle around its footprint (footprint_radius)."""
        self._client = client
        self._robot = robot
        self._agents = agents
        self._fleet = list(fleet)
        self._planar = None
        self._casters = {}
        if self.caster is RayCaster.PYBULLET:
            # Rays start in the body's frame: the scan plane follows the body up and down.
            angles = self.info.angles()
            offset = robot.sensor_height - robot.ride_height
            starts = np.zeros((self.info.beams, 3))
            starts[:, 2] = offset
            ends = np.stack([np.cos(angles) * self.config.range_max,
                             np.sin(angles) * self.config.range_max,
                             np.full(self.info.beams, offset)], axis=1)
            self._starts, self._ends = starts.tolist(), ends.tolist()
            return
        # The scan plane meets exactly the cells taller than it (walls, and for a ground
        # robot or a low flyer low obstacles and barriers too), and the world's ring of
        # blocked cells. One caster per set of opaque cells, made when first needed.
        resolution = layout.resolution
        self._padded_heights = np.pad(layout.heights, 1, constant_values=layout.border_height)
        self._padded_origin = (layout.origin[0] - resolution, layout.origin[1] - resolution)
        self._resolution = resolution
        self._levels = sorted({float(h) for h in np.unique(self._padded_heights)} - {0.0})
        self._planar = self._caster_at(robot.scan_height)

    def _caster_at(self, scan_height: float) -> PlanarRayCaster:
        """The caster of the cells opaque to a scan plane ``scan_height`` m above the ground."""
        key = bisect.bisect_right(self._levels, scan_height)
        caster = self._casters.get(key)
        if caster is None:
            caster = PlanarRayCaster(self._padded_heights > scan_height, self._resolution,
                                     self._padded_origin, self.info)
            self._casters[key] = caster
        return caster

    def scan(self) -> np.ndarray:
        """Ranges of one scan in metres (float32, a new read-only array)."""
        if self._robot is None:
            raise SessganSimError('lidar: attach() it to a spawned robot before scanning')
        config = self.config
        if self._planar is not None:
            robot = self._robot
            state = robot.state
            agents = self._agents
            scan_height = robot.scan_height
            if robot.flies:
                self._planar = self._caster_at(scan_height)
            # Agents are upright cylinders: seen when the scan plane passes between their
            # bottom and top.
            if agents is not None and not (abs(scan_height - agents.centre_height)
                                           < agents.config.height / 2):
                agents = None
            # Another robot of a fleet is seen where the scan plane passes through its body.
            others = [(other.state.x, other.state.y, other.footprint_radius)
                      for other in self._fleet
                      if other.vertical_extent[0] <= scan_height <= other.vertical_extent[1]]
            if agents is not None:
                distances = self._planar.cast(state.x, state.y, state.yaw, agents.positions,
                                              agents.config.radius, others)
            else:
                distances = self._planar.cast(state.x, state.y, state.yaw, more_circles=others)
            missed = distances >= config.range_max
            ranges = np.minimum(distances, config.range_max)
        else:
            hits = p.rayTestBatch(self._starts, self._ends, numThreads=1,
                                  parentObjectUniqueId=self._robot.body_id,
                                  collisionFilterMask=SCAN_RAY_MASK,
                                  physicsClientId=self._client)
            fractions = np.fromiter(map(_HIT_FRACTION, hits), dtype=np.float64,
                                    count=self.info.beams)
            ranges = fractions * config.range_max
            missed = fractions >= 1.0
        # From here on both casters share every step, the noise draws included.
        too_close = ranges < config.range_min
        if config.noise_std > 0:
            ranges += self._rng.normal(0.0, config.noise_std, self.info.beams)
            # np.clip, without its overhead.
            np.maximum(ranges, config.range_min, out=ranges)
            np.minimum(ranges, config.range_max, out=ranges)
        ranges[missed] = math.inf
        ranges[too_close] = -math.inf
        result = ranges.astype(np.float32)
        result.flags.writeable = False
        return result


@dataclass(frozen=True)
class RangeFinderConfig:
    """The flyer's downward range sensor (sensor_msgs/Range on ``range_down``, frame
    ``base_range_down`` at the centre of the body's underside). Lengths in metres.

    It casts one beam straight down and reads the distance to the ground or to the top of
    the obstacle below (a low obstacle; walls are taller than the flyer ever flies); agents
    are not seen by it. REP 117: a reading below ``min_range`` (the sensor inside an
    obstacle) is -inf, one beyond ``max_range`` +inf; others get Gaussian noise of
    ``noise_std`` from the episode's seeded generator, kept within the range limits.
    """

    min_range: float = 0.0
    """0: a landed flyer reads 0 (the sensor sits flush with the underside)."""
    max_range: float = 4.0
    field_of_view: float = 0.05
    """rad, as the message states it (a narrow infrared beam)."""
    noise_std: float = 0.005

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable parameter."""
        require_non_negative('range finder: min_range', self.min_range, InvalidConfigError,
                             ' m')
        if not (math.isfinite(self.max_range) and self.max_range > self.min_range):
            raise InvalidConfigError(f'range finder: max_range must exceed min_range, got '
                                     f'{self.max_range} <= {self.min_range}')
        if not (math.isfinite(self.field_of_view) and 0 < self.field_of_view < math.pi):
            raise InvalidConfigError(f'range finder: field_of_view must be in (0, pi) rad, '
                                     f'got {self.field_of_view}')
        require_non_negative('range finder: noise_std', self.noise_std, InvalidConfigError,
                             ' m')


class RangeFinder:
    """The downward range sensor of one episode (see :class:`RangeFinderConfig`)."""

    def __init__(self, config: RangeFinderConfig, rng: np.random.Generator) -> None:
        config.validate()
        self.config = config
        self._rng = rng
        self._robot: Robot | None = None
        self._heights: list[list[float]] = []
        self._origin = (0.0, 0.0)
        self._resolution = 1.0

    def attach(self, robot: Robot, layout: WorldLayout) -> None:
        """Mount the sensor under ``robot``, spawned in ``layout``'s world."""
        self._robot = robot
        resolution = layout.resolution
        # The world's ring of blocked cells closes the map; beyond it lies bare ground.
        self._heights = np.pad(layout.heights, 1,
                               constant_values=layout.border_height).tolist()
        self._origin = (layout.origin[0] - resolution, layout.origin[1] - resolution)
        self._resolution = resolution

    def surface_below(self, x: float, y: float) -> float:
        """Height (m) of what lies under the point (x, y): an obstacle's top, or 0."""
        col = math.floor((x - self._origin[0]) / self._resolution)
        row = math.floor((y - self._origin[1]) / self._resolution)
        heights = self._heights
        if 0 <= row < len(heights) and 0 <= col < len(heights[0]):
            return heights[row][col]
        return 0.0

    def exact_range(self) -> float:
        """Noise-free distance (m) from the sensor straight down to what lies below it;
        negative when the sensor is inside an obstacle."""
        robot = self._robot
        if robot is None:
            raise SessganSimError('range finder: attach() it to a spawned robot first')
        x, y = robot.position
        return robot.altitude - self.surface_below(x, y)

    def measure(self) -> float:
        """One reading in metres (REP 117: -inf too close, +inf nothing within range)."""
        config = self.config
        distance = self.exact_range()
        if distance < config.min_range:
            return -math.inf
        if distance > config.max_range:
            return math.inf
        if config.noise_std > 0:
            distance += float(self._rng.normal(0.0, config.noise_std))
            distance = min(max(distance, config.min_range), config.max_range)
        return distance


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


def contact_partners(client: int, body_id: int,
                     tolerance: float = CONTACT_TOLERANCE) -> set[int]:
    """Bodies ``body_id`` touches (its contact points from the last physics step, penetrating
    or closer than ``tolerance`` metres); empty when it touches nothing."""
    return {point[2] for point in p.getContactPoints(bodyA=body_id, physicsClientId=client)
            if point[8] <= tolerance}


class Footprint(NamedTuple):
    """An upright prism: a disc (``radius`` > 0) or a rectangle centred on the body's axis,
    between two heights. Metres."""

    radius: float
    """Disc radius; 0 for a rectangle."""
    half_length: float
    """Rectangle half extent along the body's x axis; 0 for a disc."""
    half_width: float
    """Rectangle half extent along the body's y axis; 0 for a disc."""
    bottom: float
    top: float


def upright_footprint(client: int, robot: Robot) -> Footprint | None:
    """The robot's body as an upright prism when its collision shape is one centred box or
    cylinder (every model in :mod:`sessgan_sim.robots`), else None."""
    shapes = p.getCollisionShapeData(robot.body_id, -1, physicsClientId=client)
    if len(shapes) != 1:
        return None
    geometry, dimensions, position, orientation = (shapes[0][2], shapes[0][3], shapes[0][5],
                                                   shapes[0][6])
    if any(position) or tuple(orientation) != (0.0, 0.0, 0.0, 1.0):
        return None
    if geometry == p.GEOM_CYLINDER:
        height, radius, half_length, half_width = dimensions[0], dimensions[1], 0.0, 0.0
    elif geometry == p.GEOM_BOX:
        radius, height = 0.0, dimensions[2]
        half_length, half_width = dimensions[0] / 2, dimensions[1] / 2
    else:
        return None
    return Footprint(radius, half_length, half_width, robot.ride_height - height / 2,
                     robot.ride_height + height / 2)


def _point_to_box(x: float, y: float, x_min: float, y_min: float, x_max: float,
                  y_max: float) -> float:
    """Distance (m) from a point to a filled axis-aligned rectangle; 0 inside."""
    dx = x_min - x if x < x_min else x - x_max if x > x_max else 0.0
    dy = y_min - y if y < y_min else y - y_max if y > y_max else 0.0
    return math.sqrt(dx * dx + dy * dy)


class ClearanceSensor:
    """Distance from the robot's body to the nearest obstacle or agent, up to a range.

    Analytic (the default) when the robot's body is an upright box or cylinder, as every
    model in :mod:`sessgan_sim.robots` is: obstacles are boxes standing on the ground and
    agents upright cylinders (:meth:`set_agent_heights`), and the distance between two
    upright prisms is the hypotenuse of their horizontal distance and their vertical gap.
    The horizontal distance is exact between a disc or a rotated rectangle (the robot) and
    an axis-aligned rectangle or a disc. Candidate boxes come from a cache per square of
    the reach's side, so a tick costs a few distances whatever the map's size.

    Otherwise, or with ``analytic=False`` (the baseline), it asks ``p.getClosestPoints``
    with ``range`` as the threshold, against the bodies whose bounds lie within reach. Both
    agree to about 1e-8 m along faces; near a box's corner Bullet reads up to about 0.5 mm
    more than the true distance.
    """

    def __init__(self, client: int, robot: Robot, layout: WorldLayout, range_: float,
                 analytic: bool = True) -> None:
        require_positive('clearance range', range_, InvalidConfigError, ' m')
        self.range = range_
        self._client = client
        self._robot = robot
        self._layout = layout
        self._reach = robot.footprint_radius + range_
        self.footprint = upright_footprint(client, robot) if analytic else None
        self._near: dict[tuple[int, int], list[tuple[float, float, float, float, float]]] = {}
        self._boxes = np.zeros((0, 5))
        # Until told (set_agent_heights), agents span every height: no vertical gap.
        self._agent_centre = 0.0
        self._agent_half_height = math.inf
        self._fleet: list[Robot] = []
        if self.footprint is not None:
            bottom = self.footprint.bottom
            boxes = np.array([(box.x_min, box.y_min, box.x_max, box.y_max, box.height)
                              for box in layout.obstacles]).reshape(-1, 5)
            # A box whose top lies a range or more below the body at its lowest (altitude 0)
            # never counts.
            self._boxes = boxes[bottom - boxes[:, 4] < range_]

    @property
    def analytic(self) -> bool:
        """Whether distances are computed analytically (else by pybullet)."""
        return self.footprint is not None

    def measure(self, agent_ids: list[int], agent_positions: np.ndarray,
                agent_radius: float) -> float:
        """Clearance in metres: 0 when touching, ``range`` when nothing is within range."""
        if self.footprint is not None:
            clearance = self._measure_analytic(agent_positions, agent_radius, self.footprint)
            return self._fleet_clearance(clearance, self.footprint) if self._fleet else clearance
        x, y = self._robot.position
        candidates = self._layout.obstacles_near(x, y, self._reach)
        candidates += [other.body_id for other in self._fleet]
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

    def set_fleet(self, fleet: Sequence[Robot]) -> None:
        """The other robots under test of a fleet episode: their bodies count as obstacles
        (analytically: the circle around each footprint, between its underside and top)."""
        self._fleet = list(fleet)

    def set_agent_heights(self, centre: float, height: float) -> None:
        """Where the agents fly: their centres ``centre`` m above the ground, ``height`` m
        tall (analytic clearance; pybullet's knows the bodies)."""
        self._agent_centre, self._agent_half_height = centre, height / 2

    def _fleet_clearance(self, clearance: float, footprint: Footprint) -> float:
        """``clearance`` lowered to the distance to the nearest other robot of the fleet."""
        robot = self._robot
        state = robot.state
        bottom, top = robot.vertical_extent
        rectangle = (None if footprint.radius > 0.0 else
                     _Rectangle(state.x, state.y, state.yaw, footprint.half_length,
                                footprint.half_width))
        for other in self._fleet:
            other_x, other_y = other.position
            if rectangle is None:
                horizontal = (math.hypot(other_x - state.x, other_y - state.y)
                              - footprint.radius - other.footprint_radius)
            else:
                horizontal = (rectangle.distance_to_point(other_x, other_y)
                              - other.footprint_radius)
            other_bottom, other_top = other.vertical_extent
            vertical = max(other_bottom - top, bottom - other_top, 0.0)
            clearance = min(clearance, math.hypot(max(horizontal, 0.0), vertical))
        return clearance

    def _boxes_near(self, x: float, y: float) -> list[tuple[float, float, float, float, float]]:
        """Boxes (x_min, y_min, x_max, y_max, height) within reach of a body
        centred anywhere in the square of (x, y), computed once per square."""
        size = self._reach
        key = (math.floor(x / size), math.floor(y / size))
        near = self._near.get(key)
        if near is None:
            boxes = self._boxes
            x_low, y_low = key[0] * size, key[1] * size
            dx = np.maximum(np.maximum(boxes[:, 0] - (x_low + size), x_low - boxes[:, 2]), 0.0)
            dy = np.maximum(np.maximum(boxes[:, 1] - (y_low + size), y_low - boxes[:, 3]), 0.0)
            # The margin keeps a box at exactly the reach despite rounding.
            within = dx * dx + dy * dy <= (size * (1.0 + 1e-9)) ** 2
            near = [tuple(box) for box in boxes[within].tolist()]
            self._near[key] = near
        return near

    def _measure_analytic(self, agent_positions: np.ndarray, agent_radius: float,
                          footprint: Footprint) -> float:
        robot = self._robot
        state = robot.state
        x, y = state.x, state.y
        # The body's underside and top now: a flyer's move with its altitude.
        altitude = robot.altitude
        bottom, top = footprint.bottom + altitude, footprint.top + altitude
        # Squared distances; capped at the range, as pybullet's threshold caps them.
        best = self.range * self.range
        boxes = self._boxes_near(x, y)
        # Agents: the vertical gap between the body and theirs (0 for ground robots, whose
        # agents ride at their height, and for a flyer at the agents' altitude).
        agents = agent_positions.tolist() if len(agent_positions) else []
        agent_gap = max(self._agent_centre - self._agent_half_height - top,
                        bottom - self._agent_centre - self._agent_half_height, 0.0)
        agent_vertical = agent_gap * agent_gap
        radius = footprint.radius
        if radius > 0.0:
            for x_min, y_min, x_max, y_max, box_height in boxes:
                vertical = bottom - box_height
                vertical = vertical * vertical if vertical > 0.0 else 0.0
                if vertical >= best:
                    continue
                horizontal = max(_point_to_box(x, y, x_min, y_min, x_max, y_max) - radius, 0.0)
                squared = horizontal * horizontal + vertical
                if squared < best:
                    best = squared
            for agent_x, agent_y in agents:
                gap = math.hypot(agent_x - x, agent_y - y) - radius - agent_radius
                horizontal = max(gap, 0.0)
                squared = horizontal * horizontal + agent_vertical
                if squared < best:
                    best = squared
            return math.sqrt(best)
        rectangle = _Rectangle(x, y, state.yaw, footprint.half_length, footprint.half_width)
        for x_min, y_min, x_max, y_max, box_height in boxes:
            vertical = bottom - box_height
            vertical = vertical * vertical if vertical > 0.0 else 0.0
            if vertical >= best:
                continue
            horizontal = rectangle.distance_to_box(x_min, y_min, x_max, y_max,
                                                   math.sqrt(best - vertical))
            squared = horizontal * horizontal + vertical
            if squared < best:
                best = squared
        for agent_x, agent_y in agents:
            horizontal = max(rectangle.distance_to_point(agent_x, agent_y) - agent_radius, 0.0)
            squared = horizontal * horizontal + agent_vertical
            if squared < best:
                best = squared
        return math.sqrt(best)


class _Rectangle:
    """A rectangle turned by ``yaw`` rad about its centre (x, y); half extents in m."""

    def __init__(self, x: float, y: float, yaw: float, half_length: float,
                 half_width: float) -> None:
        self.x, self.y = x, y
        self.cos, self.sin = cos, sin = math.cos(yaw), math.sin(yaw)
        self.half_length, self.half_width = half_length, half_width
        self.abs_cos, self.abs_sin = abs(cos), abs(sin)
        # Half extents of its bounding box.
        self.extent_x = half_length * self.abs_cos + half_width * self.abs_sin
        self.extent_y = half_length * self.abs_sin + half_width * self.abs_cos
        along_x, along_y = half_length * cos, half_length * sin
        across_x, across_y = -half_width * sin, half_width * cos
        self.corners = [(x + along_x + across_x, y + along_y + across_y),
                        (x + along_x - across_x, y + along_y - across_y),
                        (x - along_x + across_x, y - along_y + across_y),
                        (x - along_x - across_x, y - along_y - across_y)]

    def distance_to_point(self, px: float, py: float) -> float:
        """Distance (m) from a point to the filled rectangle; 0 inside."""
        dx, dy = px - self.x, py - self.y
        along = abs(dx * self.cos + dy * self.sin) - self.half_length
        across = abs(dy * self.cos - dx * self.sin) - self.half_width
        along, across = max(along, 0.0), max(across, 0.0)
        return math.sqrt(along * along + across * across)

    def distance_to_box(self, x_min: float, y_min: float, x_max: float, y_max: float,
                        bound: float) -> float:
        """Distance (m) between the rectangle and a filled axis-aligned one; 0 when they
        overlap. A result of ``bound`` or more may be any value >= ``bound``."""
        half_x, half_y = (x_max - x_min) / 2, (y_max - y_min) / 2
        dx, dy = (x_min + x_max) / 2 - self.x, (y_min + y_max) / 2 - self.y
        cos, sin, abs_cos, abs_sin = self.cos, self.sin, self.abs_cos, self.abs_sin
        # Separating axes: each gap is a lower bound of the distance, and all are <= 0
        # exactly when the rectangles overlap.
        gap = max(abs(dx) - half_x - self.extent_x, abs(dy) - half_y - self.extent_y,
                  abs(dx * cos + dy * sin) - self.half_length
                  - half_x * abs_cos - half_y * abs_sin,
                  abs(dy * cos - dx * sin) - self.half_width
                  - half_x * abs_sin - half_y * abs_cos)
        if gap <= 0.0:
            return 0.0
        if gap >= bound:
            return gap
        # Apart, two convex polygons are closest at a corner of one of them.
        distance = min(_point_to_box(cx, cy, x_min, y_min, x_max, y_max)
                       for cx, cy in self.corners)
        for corner_x in (x_min, x_max):
            for corner_y in (y_min, y_max):
                distance = min(distance, self.distance_to_point(corner_x, corner_y))
        return distance
