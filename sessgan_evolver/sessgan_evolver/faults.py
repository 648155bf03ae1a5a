"""Failures, distinct faults and their confirmation: how fault-finding is counted.

**Valid failure**: a controller failure as sessgan_sim defines it
(``sessgan_sim.metrics.is_controller_failure``, the rule the simulator node keeps failure bags
by): in a valid test (a map whose route certificate holds, ``Environment.feasible``), a
contact the robot under test caused, or the goal not reached (timeout, stuck). An agent
driving into a robot that stood still is recorded but is no failure.

**Distinct faults.** A valid failure's *fault* is its first fault event: the first contact
the robot caused (kind ``collision_static`` against a wall, barrier or low obstacle,
``collision_agent`` when it moved into an agent, ``collision_robot`` when a robot of a fleet
moved into another; at that robot's position when the contact began), or, without one, where
the robot ended (kind ``stuck`` or ``timeout``; in a fleet the robot the episode's outcome
comes from). Two valid failures are the same fault when

1. their kinds are equal,
2. their fault places fall into the same coarse cell (squares of ``FaultRule.coarse_cells``
   map cells, counted from the map's origin), and
3. the map around that coarse cell (the coarse cell widened by ``FaultRule.context_cells``
   map cells on each side, beyond the grid counting as outside) is identical.

So the same local situation met the same way counts once, in one map or in many (a mutation
far from the place makes no new fault), while a change of the layout where it happened, or
another kind of failure, is a new one. The coarse grid can split one physical spot between
two neighbouring cells; the rule accepts that rather than merging distinct spots.

**Confirmation.** A distinct fault is re-run R times from its first occurrence (same map,
same simulator seed); it is *confirmed* when every re-run is a valid failure of the same kind
in the same or a neighbouring coarse cell (:func:`same_place`: a stack in clocked mode, not
exactly repeatable, that got stuck 28 cm from where it did before, across a cell's edge, shows
the same fault). In-process lockstep episodes are deterministic, so they also reproduce
*exactly* (the same key; and the same outcome, collisions, ticks and risk), which is counted
separately.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from sessgan_core.environment import Environment
from sessgan_evolver.episode_runner import EpisodeTrace
from sessgan_evolver.errors import FaultError
from sessgan_sim.metrics import ContactKind, is_controller_failure

EXACT_FIELDS = ('outcome', 'collisions', 'fault_collisions', 'ticks', 'risk_score',
                'proximity_time')
"""Metrics two runs must share to reproduce exactly."""

OUTSIDE = -1
"""Context value of cells beyond the grid."""


def is_valid_failure(metrics: Mapping[str, Any]) -> bool:
    """sessgan_sim's controller-failure rule applied to a metrics dict."""
    return is_controller_failure(SimpleNamespace(
        feasible=bool(metrics.get('feasible')),
        fault_collisions=int(metrics.get('fault_collisions') or 0),
        outcome=metrics.get('outcome')))


@dataclass(frozen=True)
class FaultRule:
    """The grouping of the module docstring, in map cells."""

    coarse_cells: int = 4
    """Side of a coarse cell in map cells (2 m in the factory and drone area, 4 m on the
    race track)."""
    context_cells: int = 2
    """Map cells around the coarse cell whose layout is part of the fault."""

    def validate(self) -> None:
        if self.coarse_cells < 1:
            raise FaultError(f'coarse_cells must be >= 1, got {self.coarse_cells}')
        if self.context_cells < 0:
            raise FaultError(f'context_cells must be >= 0, got {self.context_cells}')


@dataclass(frozen=True, order=True)
class FaultKey:
    """What makes a fault distinct (module docstring)."""

    kind: str
    row: int
    """Coarse cell row (y) of the fault place."""
    col: int
    """Coarse cell column (x)."""
    context: str
    """Hex digest of the map around the coarse cell."""

    @property
    def label(self) -> str:
        """A short, file-name-safe name, e.g. 'collision_static-r3c5-1a2b3c4d'."""
        return f'{self.kind}-r{self.row}c{self.col}-{self.context[:8]}'

    def to_dict(self) -> dict[str, Any]:
        return {'kind': self.kind, 'row': self.row, 'col': self.col, 'context': self.context}


@dataclass(frozen=True)
class FaultEvent:
    """The first fault event of a valid failure."""

    kind: str
    x: float
    """m, map frame."""
    y: float
    time: float
    """Sim seconds (the end of the episode for stuck and timeout)."""


FAULT_KIND_OF_CONTACT = {ContactKind.STATIC.value: 'collision_static',
                         ContactKind.ROBOT_INTO_AGENT.value: 'collision_agent',
                         ContactKind.ROBOT_INTO_ROBOT.value: 'collision_robot'}
"""Fault kinds of the contact kinds that are the robot's fault (sessgan_sim.metrics:
every kind but those in NOT_FAULT_KINDS)."""


def failing_robot(metrics: Mapping[str, Any], robots: int) -> int:
    """The robot a fleet episode's outcome comes from (its ``failed_leg``, which in a fleet
    counts robots, in a mission legs); 0 for one robot; -1 when a fleet's robots all reached
    their goals without a fault."""
    return int(metrics.get('failed_leg', -1)) if robots > 1 else 0


def first_fault_event(metrics: Mapping[str, Any], trace: EpisodeTrace) -> FaultEvent:
    """The first contact a robot under test caused (from the metrics' contact events, at
    that robot's place), else where the failing robot ended (kind = the outcome): in a fleet
    the robot the episode's outcome comes from (``failed_leg``), else the one robot."""
    for contact in metrics.get('contacts') or ():
        kind = FAULT_KIND_OF_CONTACT.get(str(contact.get('kind')))
        if kind is not None:
            return FaultEvent(kind, float(contact['x']), float(contact['y']),
                              float(contact['time']))
    if int(metrics.get('fault_collisions') or 0) > 0:
        raise FaultError('the metrics count a fault collision but list no contact event the '
                         'robot caused')
    robot = failing_robot(metrics, len(trace.fleet) + 1)
    if robot > len(trace.fleet):
        raise FaultError(f'the metrics name robot r{robot} as failing, the trace has '
                         f'{len(trace.fleet) + 1} robots')
    ended = trace.fleet[robot - 1] if robot > 0 else trace
    if not len(ended.poses):
        raise FaultError('the trace has no robot pose')
    x, y, _ = (float(v) for v in ended.poses[-1])
    return FaultEvent(str(metrics.get('outcome')), x, y, float(ended.times[-1]))


def fault_key(environment: Environment, event: FaultEvent, rule: FaultRule) -> FaultKey:
    """The key of a fault event in ``environment`` (module docstring)."""
    rule.validate()
    map_row, map_col = environment.cell_of(event.x, event.y)
    row = math.floor(map_row / rule.coarse_cells)
    col = math.floor(map_col / rule.coarse_cells)
    return FaultKey(event.kind, int(row), int(col),
                    place_context(np.asarray(environment.occupancy), row, col, rule))


def place_context(occupancy: np.ndarray, row: int, col: int, rule: FaultRule) -> str:
    """The ``context`` digest of coarse cell (row, col) of an occupancy grid (the map
    around it, module docstring)."""
    top, left = row * rule.coarse_cells - rule.context_cells, col * rule.coarse_cells \
        - rule.context_cells
    side = rule.coarse_cells + 2 * rule.context_cells
    patch = np.full((side, side), OUTSIDE, dtype=np.int16)
    rows = slice(max(top, 0), min(top + side, occupancy.shape[0]))
    cols = slice(max(left, 0), min(left + side, occupancy.shape[1]))
    if rows.start < rows.stop and cols.start < cols.stop:
        patch[rows.start - top:rows.stop - top, cols.start - left:cols.stop - left] = \
            occupancy[rows, cols]
    return hashlib.sha256(patch.tobytes() + f'{side}'.encode()).hexdigest()


def key_of_failure(environment: Environment, metrics: Mapping[str, Any],
                   trace: EpisodeTrace | None, rule: FaultRule) -> FaultKey | None:
    """The fault key of a valid failure (None for anything else)."""
    if not is_valid_failure(metrics):
        return None
    if trace is None:
        raise FaultError(f'episode {environment.id}: a fault key needs the episode trace')
    return fault_key(environment, first_fault_event(metrics, trace), rule)


def exactly_equal(first: Mapping[str, Any], second: Mapping[str, Any]) -> bool:
    """Whether two runs' metrics agree on EXACT_FIELDS."""
    return all(first.get(name) == second.get(name) for name in EXACT_FIELDS)


@dataclass(frozen=True)
class Confirmation:
    """The re-runs of one distinct fault."""

    repeats: int
    reproduced: int
    """Re-runs that were valid failures at the same place (:func:`same_place`)."""
    exact: int
    """Re-runs whose metrics equal the original's on EXACT_FIELDS."""
    wall_time: float
    """Wall seconds of the re-runs."""

    @property
    def confirmed(self) -> bool:
        return self.repeats > 0 and self.reproduced == self.repeats


@dataclass
class FaultEntry:
    """One distinct fault and the episodes that showed it."""

    key: FaultKey
    occurrences: list[int] = field(default_factory=list)
    """Indices (into the episode list) of the episodes with this fault, in order."""
    confirmation: Confirmation | None = None

    @property
    def first(self) -> int:
        return self.occurrences[0]


def group_faults(keys: Sequence[FaultKey | None]) -> list[FaultEntry]:
    """Distinct faults of a sequence of episodes' keys (None: no valid failure), in the
    order of their first occurrence."""
    entries: dict[FaultKey, FaultEntry] = {}
    for index, key in enumerate(keys):
        if key is None:
            continue
        entry = entries.get(key)
        if entry is None:
            entry = entries[key] = FaultEntry(key)
        entry.occurrences.append(index)
    return list(entries.values())


Rerun = Callable[[], tuple[Mapping[str, Any], FaultKey | None, float]]
"""Runs a fault's episode again: (metrics, fault key or None, wall seconds)."""


def same_place(key: FaultKey, other: FaultKey | None) -> bool:
    """Whether a re-run's fault ``other`` shows the fault ``key`` again: the same kind in the
    same or a neighbouring coarse cell (the coarse grid can split one spot between two)."""
    return (other is not None and other.kind == key.kind
            and abs(other.row - key.row) <= 1 and abs(other.col - key.col) <= 1)


def confirm(entry: FaultEntry, original_metrics: Mapping[str, Any], rerun: Rerun,
            repeats: int) -> Confirmation:
    """Re-run ``entry``'s first episode ``repeats`` times and store the Confirmation."""
    if repeats < 0:
        raise FaultError(f'repeats must be >= 0, got {repeats}')
    reproduced = exact = 0
    wall = 0.0
    for _ in range(repeats):
        metrics, key, seconds = rerun()
        wall += seconds
        reproduced += same_place(entry.key, key)
        exact += int(exactly_equal(metrics, original_metrics))
    entry.confirmation = Confirmation(repeats, reproduced, exact, wall)
    return entry.confirmation


SITUATION_CELLS = 0.1
"""Share of map cells two failing maps must differ in to be different fault situations."""
STRICT_SITUATION_CELLS = 0.25
"""A stricter share, reported beside SITUATION_CELLS, so a gain that holds only at the
search's own threshold shows."""


def same_situation(key: FaultKey, occupancy: np.ndarray, other: FaultKey,
                   other_occupancy: np.ndarray, share: float = SITUATION_CELLS) -> bool:
    """Whether two faults are one *fault situation*: the same kind and coarse cell on maps
    that differ in fewer than ``share`` of their cells (a local variant of a failing map is
    the same situation, though the exact-context rule counts it as a new fault)."""
    return (key.kind == other.kind and key.row == other.row and key.col == other.col
            and np.shape(occupancy) == np.shape(other_occupancy)
            and float(np.mean(np.asarray(occupancy) != np.asarray(other_occupancy))) < share)


@dataclass
class SituationArchive:
    """Fault situations found so far: a representative fault and its map for each."""

    share: float = SITUATION_CELLS
    known: list[tuple[FaultKey, np.ndarray]] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.known)

    def add(self, key: FaultKey, occupancy: np.ndarray) -> bool:
        """Remember the fault ``key`` on ``occupancy``; True when it is a new situation."""
        occupancy = np.asarray(occupancy)
        if any(same_situation(key, occupancy, other, other_occupancy, self.share)
               for other, other_occupancy in self.known):
            return False
        self.known.append((key, occupancy.copy()))
        return True

    def known_on(self, occupancy: np.ndarray, cells: set[tuple[int, int]]) -> int:
        """How many known situations lie in one of the coarse ``cells`` of a map that differs
        from theirs in fewer than ``share`` of its cells (where a failure would repeat one)."""
        occupancy = np.asarray(occupancy)
        return sum((key.row, key.col) in cells and np.shape(other) == np.shape(occupancy)
                   and float(np.mean(other != occupancy)) < self.share
                   for key, other in self.known)
