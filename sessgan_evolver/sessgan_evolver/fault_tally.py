"""Valid failures and distinct faults a campaign has found so far: what its user reads first.

Faults are counted as ``compare`` counts them (sessgan_evolver.faults: a valid failure's
fault key, two failures with one key are one fault); a campaign re-runs nothing, so its
faults are *distinct*, not confirmed. An episode run in process reaches the
:class:`FaultTracker` with its trace (as the evaluator's observer); an episode of a ROS
worker comes back as a metrics message without contact places, so its key is read from the
episode's failure bag (contacts from episode.json, where the robot ended from its odometry).
A valid failure with neither (failure bags off, or written on another machine) still counts
as a failure; its fault is *unplaced* and counted apart.

Distinct faults alone overstate what a search found: a small variant of a failing map that
fails at the same place is a new distinct fault. So the tally also counts *fault situations*
(sessgan_evolver.faults.same_situation: the same kind and place on maps that differ in fewer
than 10 % of their cells are one), the count the screened search's novelty and ``compare``
use. Each situation's first map is kept in the run (``situations.npz``), so a resumed
campaign goes on comparing against them.
"""

from __future__ import annotations

import hashlib
import io
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_core.environment import Environment
from sessgan_evolver.bag_reading import iter_bag_messages, read_episode_json
from sessgan_evolver.episode_runner import EpisodeRun, EpisodeTrace
from sessgan_evolver.errors import BagReadError, FaultError
from sessgan_evolver.faults import (
    FaultKey,
    FaultRule,
    SituationArchive,
    fault_key,
    first_fault_event,
    is_valid_failure,
    key_of_failure,
    place_context,
)
from sessgan_sim.bag_recording import jazzy_typestore

UNPLACED = '?'
"""The fault label of a valid failure whose place is unknown (no trace, no bag)."""


def trace_from_bag(bag: str | Path) -> tuple[EpisodeTrace, dict[str, Any]]:
    """The robot's path (odometry; a fleet's r0, with r1, r2, ... as its ``fleet``) as a
    trace, and the episode.json metrics (with the contact events) of a failure bag.
    BagReadError if it holds neither."""
    episode = read_episode_json(bag) or {}
    metrics = episode.get('metrics')
    if not isinstance(metrics, dict):
        raise BagReadError(f'bag {bag} has no metrics in its episode.json')
    store = jazzy_typestore()
    paths: dict[str, list[tuple[float, float, float]]] = {}
    for message in iter_bag_messages(bag):
        if message.topic.rsplit('/', 1)[-1] != 'odom':
            continue
        odom: Any = store.deserialize_cdr(message.data, message.msgtype)
        stamp = odom.header.stamp
        paths.setdefault(message.topic, []).append(
            (float(stamp.sec) + 1e-9 * float(stamp.nanosec),
             float(odom.pose.pose.position.x), float(odom.pose.pose.position.y)))
    fleet = sorted((int(match.group(1)), topic) for topic in paths
                   if (match := re.search(r'/r(\d+)/odom$', topic)))
    topics = [topic for _, topic in fleet] or list(paths)[:1]
    if not topics:
        raise BagReadError(f'bag {bag} has no odometry')
    traces = []
    for topic in topics:
        table = np.asarray(paths[topic], dtype=float)
        traces.append(EpisodeTrace(
            times=table[:, 0], poses=np.column_stack([table[:, 1:3], np.zeros(len(table))]),
            twists=np.zeros((len(table), 3)), commands=np.zeros((max(len(table) - 1, 0), 4)),
            agents=np.zeros((len(table), 0, 2))))
    trace, trace.fleet = traces[0], traces[1:]
    return trace, metrics


def key_from_bag(environment: Environment, bag: str | Path, rule: FaultRule) -> FaultKey:
    """The fault key of a valid failure from its failure bag (module docstring)."""
    trace, metrics = trace_from_bag(bag)
    return fault_key(environment, first_fault_event(metrics, trace), rule)


class FaultTracker:
    """Fault labels of a campaign's episodes, however they ran (module docstring)."""

    def __init__(self, rule: FaultRule | None = None) -> None:
        self.rule = rule or FaultRule()
        self._traced: dict[str, FaultKey | None] = {}
        """Keys of in-process episodes by environment id, until their result is told."""

    def observe(self, environment: Environment, seed: int, run: EpisodeRun,
                origin: str = '') -> None:
        """An InProcessEvaluator's observer: keeps the key from the episode's trace."""
        self._traced[environment.id] = key_of_failure(environment, run.metrics, run.trace,
                                                      self.rule)

    def attach(self, evaluator: object) -> None:
        """Observe every episode of ``evaluator`` if it runs them in process (it has an
        ``observer``), beside the observer it had."""
        if not hasattr(evaluator, 'observer'):
            return
        previous = evaluator.observer

        def observe(environment: Environment, seed: int, run: EpisodeRun, origin: str) -> None:
            self.observe(environment, seed, run, origin)
            if previous is not None:
                previous(environment, seed, run, origin)

        evaluator.observer = observe

    def key_of(self, environment: Environment, metrics: Mapping[str, Any]) -> FaultKey | None:
        """The fault key of a valid failure, from its trace (in process) or its failure bag;
        None for an episode that is no valid failure or when neither says where it happened."""
        traced = self._traced.pop(environment.id, None)
        if not is_valid_failure(metrics):
            return None
        if traced is not None:
            return traced
        bag = str(metrics.get('bag_path') or '')
        if not bag or not Path(bag).exists():
            return None
        try:
            return key_from_bag(environment, bag, self.rule)
        except (BagReadError, FaultError):
            return None


def fault_label(metrics: Mapping[str, Any], key: FaultKey | None) -> str:
    """The ``fault`` column of an episode: '' for no valid failure, else its key's label or
    UNPLACED."""
    if not is_valid_failure(metrics):
        return ''
    return key.label if key is not None else UNPLACED


def key_from_label(label: str, occupancy: np.ndarray, rule: FaultRule) -> FaultKey | None:
    """The fault key an episode row's ``fault`` label names, its context digest taken again
    from the episode's map (the label keeps 8 characters of it); None for '' and UNPLACED."""
    if label in ('', UNPLACED):
        return None
    kind, _, rest = label.rpartition('-r')
    place, _, prefix = rest.partition('-')
    row, _, col = place.partition('c')
    if not (kind and row.isdigit() and col.isdigit() and prefix):
        raise FaultError(f'not a fault label: {label!r}')
    context = place_context(occupancy, int(row), int(col), rule)
    if not context.startswith(prefix):
        raise FaultError(f'fault label {label!r} does not match its map around '
                         f'r{row}c{col}')
    return FaultKey(kind, int(row), int(col), context)


def origin_family(origin: str) -> str:
    """An episode's origin without the parents, members or generation it names: 'child of
    collision_static r3c4 by local_0.8' -> 'child by local_0.8', 'generation 2 crossover 0x3
    + paint' -> 'crossover + paint', 'generation 2 from 1 + move' -> 'one parent + move';
    SESS-GAN's 'generation 2 member 5' -> 'evolved generations' ('generation 0' for the
    first)."""
    member = re.fullmatch(r'generation (\d+) member \d+', origin)
    if member:
        return 'generation 0' if member.group(1) == '0' else 'evolved generations'
    origin = re.sub(r'^generation \d+ ', '', origin)
    child = re.fullmatch(r'child of .* by (\S+)', origin)
    if child:
        return f'child by {child.group(1)}'
    origin = re.sub(r'^from \d+', 'one parent', origin)
    return re.sub(r'^crossover \d+x\d+', 'crossover', origin) or 'unlabelled'


@dataclass
class OriginFigures:
    """What the episodes of one origin family gave: the distinct faults each was the first to
    show, and how many of those were new fault situations."""

    episodes: int = 0
    faults: int = 0
    situations: int = 0


def origin_rows(table: Mapping[str, OriginFigures], prefix: str = '') -> list[str]:
    """Markdown rows of ``table``, the origin with the most episodes first, each after
    ``prefix`` (columns before the origin's): origin, episodes, new distinct faults and new
    situations (share of the origin's episodes and count)."""
    return [f'| {prefix}{origin} | {row.episodes} | {row.faults / row.episodes:.1%} '
            f'({row.faults}) | {row.situations / row.episodes:.1%} ({row.situations}) |'
            for origin, row in sorted(table.items(), key=lambda item: -item[1].episodes)]


@dataclass
class FaultTally:
    """Cumulative counts over a campaign's episodes, in the order they were recorded."""

    episodes: int = 0
    valid_failures: int = 0
    unplaced: int = 0
    """Valid failures whose fault could not be placed (not among ``faults``)."""
    faults: dict[str, int] = field(default_factory=dict)
    """Distinct fault label -> 1-based episode that first showed it."""
    first_failure: int | None = None
    """1-based episode of the first valid failure."""
    fault_situations: int = 0
    situations: SituationArchive = field(default_factory=SituationArchive)
    """The first fault and map of each situation, to compare new faults against."""
    situation_ids: list[str] = field(default_factory=list)
    """The environment id of each situation's first episode."""
    situations_counted: bool = True
    """False for a run recorded before situations were (no 'situation' column)."""
    saved_situations: int = -1
    """Situations in the file :meth:`save_situations` last wrote (-1: none written yet)."""

    def add(self, label: str, key: FaultKey | None = None,
            environment: Environment | None = None) -> bool:
        """One more episode with its fault label ('' for no valid failure) and, for a placed
        fault, its key and environment; True when it is a new fault situation."""
        self.episodes += 1
        if not label:
            return False
        self.valid_failures += 1
        if self.first_failure is None:
            self.first_failure = self.episodes
        if label == UNPLACED:
            self.unplaced += 1
            return False
        self.faults.setdefault(label, self.episodes)
        if key is None or environment is None \
                or not self.situations.add(key, environment.occupancy):
            return False
        self.situation_ids.append(environment.id)
        self.fault_situations += 1
        return True

    @classmethod
    def from_rows(cls, rows: Iterable[Mapping[str, Any]],
                  situations: str | Path | None = None) -> FaultTally:
        """The tally of recorded episode rows (their 'fault' and 'situation' columns), e.g.
        on resume, with the situations' maps kept in ``situations`` (:meth:`save_situations`;
        None: not needed, as for a report)."""
        tally = cls()
        rows = list(rows)
        firsts = set()
        for row in rows:
            tally.add(str(row.get('fault') or ''))
            if row.get('situation') is True:
                firsts.add(str(row.get('environment_id')))
        tally.fault_situations = len(firsts)
        tally.situations_counted = not rows or 'situation' in rows[0]
        if situations is not None and Path(situations).exists():
            # Only those of rows still recorded: a resume drops the rows of a batch it re-runs.
            for environment_id, key, occupancy in load_situations(situations):
                if environment_id in firsts:
                    tally.situations.known.append((key, occupancy))
                    tally.situation_ids.append(environment_id)
        return tally

    @property
    def distinct_faults(self) -> int:
        return len(self.faults)

    def save_situations(self, path: str | Path) -> None:
        """Each situation's fault and first map, for a resumed run (:func:`load_situations`);
        written again only when a situation was added since."""
        known = self.situations.known
        if len(known) == self.saved_situations:
            return
        arrays = {'ids': np.array(self.situation_ids, dtype=str),
                  'kinds': np.array([key.kind for key, _ in known], dtype=str),
                  'places': np.array([(key.row, key.col) for key, _ in known],
                                     dtype=np.int64).reshape(-1, 2),
                  'contexts': np.array([key.context for key, _ in known], dtype=str)}
        arrays.update({f'map_{index}': np.asarray(occupancy, dtype=np.int8)
                       for index, (_, occupancy) in enumerate(known)})
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)  # type: ignore[arg-type]  # numpy's stub types allow_pickle
        atomic_write_bytes(path, buffer.getvalue())
        self.saved_situations = len(known)

    def per_episode(self, count: int) -> float:
        return count / self.episodes if self.episodes else 0.0

    def columns(self) -> dict[str, int]:
        """The cumulative counts as columns of a generation row."""
        return {'episodes_so_far': self.episodes, 'valid_failures_so_far': self.valid_failures,
                'distinct_faults_so_far': self.distinct_faults,
                'fault_situations_so_far': self.fault_situations,
                'unplaced_failures_so_far': self.unplaced}

    def line(self) -> str:
        """The console's lead: cumulative counts and their rate per episode."""
        text = (f'{self.valid_failures} valid failures '
                f'({self.per_episode(self.valid_failures):.3f}/episode), '
                f'{self.distinct_faults} distinct faults '
                f'({self.per_episode(self.distinct_faults):.3f}/episode)')
        if self.situations_counted:
            text += f', {self.fault_situations} fault situations'
        if self.unplaced:
            text += f' + {self.unplaced} unplaced'
        return text + f' in {self.episodes} episodes'


def load_situations(path: str | Path) -> list[tuple[str, FaultKey, np.ndarray]]:
    """(environment id, fault key, map) of each situation :meth:`FaultTally.save_situations`
    kept; FaultError if the file is unreadable."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return [(str(environment_id), FaultKey(str(kind), int(row), int(col), str(context)),
                     np.array(data[f'map_{index}']))
                    for index, (environment_id, kind, (row, col), context) in enumerate(zip(
                        data['ids'], data['kinds'], data['places'], data['contexts']))]
    except (OSError, ValueError, KeyError) as err:
        raise FaultError(f'cannot read the fault situations {str(path)!r}: {err}') from err


def map_digest(cells: np.ndarray) -> str:
    """A short digest of a map's cells: a resumed search checks it proposes the same maps."""
    array = np.ascontiguousarray(np.asarray(cells, dtype=np.int16))
    return hashlib.sha256(array.tobytes() + str(array.shape).encode()).hexdigest()[:16]
