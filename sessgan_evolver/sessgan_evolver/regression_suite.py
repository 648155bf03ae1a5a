"""Regression suites: recorded scenarios re-run against the robot under test, judged for CI.

A suite lists scenarios, each a failure bag whose episode.json holds everything that
re-simulates it (map, start, goal, seeds, robot, simulator settings) and the failure it
showed. It is a YAML file (:func:`load_suite`, written by :func:`write_suite_file`) or a
directory of bags (:func:`suite_from_bag_directory`). This module holds what needs no ROS:
reading and checking suites, judging attempts (:func:`classify`), deciding how many more
attempts a scenario needs (:class:`ScenarioProgress`) and writing the JUnit XML, markdown and
CSV results; ``suite_cli`` runs the episodes.

Attempts: a lockstep episode in process is exact, so one result is the verdict. A clocked one
depends on wall-clock timing, so it runs ``1 + retries`` times: pass when every result passes,
fail when every one fails, flaky when they disagree. A harness outcome (the controller did
not answer, the episode was cancelled, the simulator could not build the recorded map) is no
result: the attempt is run again, and after ``harness_tries`` of them in a row the scenario is
a harness error, never a pass or a fail.
"""

from __future__ import annotations

import csv
import enum
import io
import math
import os
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_evolver.errors import BagReadError, SuiteError
from sessgan_sim.metrics import FAILURE_OUTCOMES, Outcome
from sessgan_sim.metrics import HARNESS_OUTCOMES as SIM_HARNESS_OUTCOMES

SUITE_FORMAT = 1
"""Version of the suite file's layout (``format:`` in the file)."""

EPISODE_FILE = 'episode.json'

HARNESS_OUTCOMES = frozenset({*(str(outcome) for outcome in SIM_HARNESS_OUTCOMES),
                              'invalid_environment'})
"""Outcomes that say nothing about the robot under test: sessgan_sim's harness outcomes and,
since a suite's scenarios were valid tests when recorded, invalid_environment on a re-run
(settings the simulator could not build), not the map's."""


RESULT_OUTCOMES = frozenset(str(outcome) for outcome in Outcome
                            if str(outcome) not in HARNESS_OUTCOMES)
"""Outcomes a suite file may expect: the results of a valid test."""

NUMERIC_PROPERTIES = (
    'simulation_time', 'collisions', 'fault_collisions', 'min_clearance', 'proximity_time',
    'distance_travelled', 'final_distance_to_goal', 'risk_score', 'fault_risk_score', 'ticks',
    'success', 'time_to_goal', 'path_length', 'path_length_ratio', 'mean_clearance',
    'linear_jerk', 'angular_jerk', 'mean_speed', 'wall_time')
"""Metrics reported per scenario (JUnit properties, CSV columns) when the episode has them."""


class AttemptKind(enum.StrEnum):
    PASS = 'pass'
    FAIL = 'fail'
    HARNESS = 'harness'


class Verdict(enum.StrEnum):
    PASS = 'pass'
    FAIL = 'fail'
    FLAKY = 'flaky'
    ERROR = 'error'
    """Harness error: no result in ``harness_tries`` attempts."""
    NOT_RUN = 'not_run'
    """Interrupted before the scenario had a verdict."""


@dataclass(frozen=True)
class SuiteEntry:
    """One scenario of a suite."""

    name: str
    bag: Path
    """The failure bag directory that re-simulates it."""
    episode: Mapping[str, Any]
    """The bag's episode.json."""
    expected_outcome: str = ''
    """The failure it showed when recorded (outcome of the recorded episode)."""
    expected_fault_collisions: int = 0

    @property
    def scenario(self) -> str:
        return str(self.episode.get('scenario', ''))

    @property
    def environment_id(self) -> str:
        return str(self.episode.get('environment_id', ''))

    @property
    def mode(self) -> str:
        simulator = self.episode.get('simulator')
        mode = simulator.get('mode') if isinstance(simulator, Mapping) else None
        return str(mode or self.episode.get('mode') or 'lockstep')


@dataclass(frozen=True)
class Suite:
    name: str
    entries: tuple[SuiteEntry, ...]
    source: Path


# ---- reading ----------------------------------------------------------------------------


def _read_episode(bag: Path, where: str) -> dict[str, Any]:
    import json

    path = bag / EPISODE_FILE
    if not bag.is_dir():
        raise SuiteError(f'{where}: bag {bag} does not exist')
    if not (bag / 'metadata.yaml').is_file():
        raise SuiteError(f'{where}: {bag} is not a rosbag2 bag (no metadata.yaml)')
    if not path.is_file():
        raise SuiteError(f'{where}: bag {bag} has no {EPISODE_FILE} to re-simulate from')
    try:
        episode = json.loads(path.read_text(encoding='utf-8'))
    except (OSError, ValueError) as err:
        raise SuiteError(f'{where}: {path} is unreadable or not JSON: {err}') from err
    if not isinstance(episode, dict):
        raise SuiteError(f'{where}: {path} does not hold a JSON object')
    from sessgan_evolver.bag_reading import check_episode_fields

    try:
        check_episode_fields(episode, path)
    except BagReadError as err:
        raise SuiteError(f'{where}: {err}') from err
    return episode


def entry_from_bag(bag: Path, name: str = '', where: str = '') -> SuiteEntry:
    """The scenario of failure bag ``bag`` (its recorded outcome is the expected failure)."""
    bag = Path(bag)
    where = where or f'bag {bag}'
    episode = _read_episode(bag, where)
    metrics = episode.get('metrics') or {}
    return SuiteEntry(name or bag.name, bag, episode, str(metrics.get('outcome', '')),
                      int(metrics.get('fault_collisions', 0) or 0))


def bags_below(directory: Path) -> list[Path]:
    """Every failure bag below ``directory`` (a directory with metadata.yaml and
    episode.json), sorted by path; staging directories of bags being written are skipped."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(path.parent for path in directory.rglob(EPISODE_FILE)
                  if (path.parent / 'metadata.yaml').is_file()
                  and '.tmp-' not in path.relative_to(directory).as_posix())


def suite_from_bag_directory(directory: Path) -> Suite:
    """The suite of every failure bag below ``directory`` (:func:`bags_below`)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise SuiteError(f'{directory} is not a directory of failure bags')
    bags = bags_below(directory)
    if not bags:
        raise SuiteError(f'{directory} holds no failure bag (no directory with metadata.yaml and '
                         f'{EPISODE_FILE}): an empty suite')
    names = unique_names(str(bag.relative_to(directory)) for bag in bags)
    return Suite(directory.name, tuple(entry_from_bag(bag, name)
                                       for bag, name in zip(bags, names)), directory)


def unique_names(names: Iterable[str]) -> list[str]:
    """``names`` with later duplicates suffixed ``-2``, ``-3`` ... (testcase names are keys)."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        count = seen.get(name, 0) + 1
        seen[name] = count
        out.append(name if count == 1 else f'{name}-{count}')
    return out


_ENTRY_KEYS = {'name', 'bag', 'scenario', 'environment_id', 'expected', 'seed', 'controller',
               'settings', 'robot'}


def load_suite(path: Path) -> Suite:
    """Read and check suite file ``path`` (YAML, :func:`write_suite_file`'s layout).

    Every entry needs ``bag`` (relative to the file's directory or absolute); ``scenario`` and
    ``environment_id``, when given, must be the bag's (else it is a bag of another scenario).
    SuiteError naming the entry for anything wrong; nothing is run before the whole file is
    checked.
    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as err:
        raise SuiteError(f'cannot read suite file {path}: {err}') from err
    except yaml.YAMLError as err:
        raise SuiteError(f'suite file {path} is not valid YAML: {err}') from err
    if not isinstance(document, dict):
        raise SuiteError(f'suite file {path} must hold a mapping with a "scenarios" list')
    version = document.get('format', SUITE_FORMAT)
    if version != SUITE_FORMAT:
        raise SuiteError(f'suite file {path}: format {version!r} is not supported (this '
                         f'version reads format {SUITE_FORMAT})')
    scenarios = document.get('scenarios')
    if scenarios is None or scenarios == []:
        raise SuiteError(f'suite file {path} lists no scenarios: an empty suite')
    if not isinstance(scenarios, list):
        raise SuiteError(f'suite file {path}: "scenarios" must be a list')
    entries = []
    names: set[str] = set()
    for number, item in enumerate(scenarios, start=1):
        where = f'{path} scenario {number}'
        if not isinstance(item, dict):
            raise SuiteError(f'{where}: must be a mapping with at least "bag"')
        if isinstance(item.get('name'), str):
            where = f'{path} scenario {number} ({item["name"]})'
        unknown = sorted(set(item) - _ENTRY_KEYS)
        if unknown:
            raise SuiteError(f'{where}: unknown field(s) {unknown}')
        if not isinstance(item.get('bag'), str) or not item['bag']:
            raise SuiteError(f'{where}: field "bag" (the failure bag directory) is missing')
        bag = Path(item['bag'])
        if not bag.is_absolute():
            bag = path.parent / bag
        entry = entry_from_bag(bag, str(item.get('name') or bag.name), where)
        for key in ('scenario', 'environment_id'):
            if key in item and str(item[key]) != str(entry.episode.get(key, '')):
                raise SuiteError(
                    f'{where}: the suite names {key} {item[key]!r} but bag {bag} holds '
                    f'{entry.episode.get(key)!r} (a bag of another scenario)')
        expected = item.get('expected') or {}
        if not isinstance(expected, dict):
            raise SuiteError(f'{where}: "expected" must be a mapping (outcome, '
                             'fault_collisions)')
        if 'outcome' in expected and expected['outcome'] not in RESULT_OUTCOMES:
            raise SuiteError(f'{where}: expected outcome {expected["outcome"]!r} is none of '
                             f'{", ".join(sorted(RESULT_OUTCOMES))}')
        if entry.name in names:
            raise SuiteError(f'{where}: the name {entry.name!r} is used twice')
        names.add(entry.name)
        entries.append(SuiteEntry(
            entry.name, entry.bag, entry.episode,
            str(expected.get('outcome', entry.expected_outcome)),
            int(expected.get('fault_collisions', entry.expected_fault_collisions))))
    return Suite(str(document.get('name') or path.stem), tuple(entries), path)


SUITE_FILE = 'suite.yaml'
"""The name campaign, compare and evaluate give the suite file in their output folder."""


def load_suite_source(source: Path) -> Suite:
    """A suite file, a folder holding one (a campaign run, an evaluate or compare output), a
    directory of bags, or one bag (a suite of one)."""
    source = Path(source)
    if not source.exists():
        raise SuiteError(f'{source} does not exist (give a suite file or a directory of bags)')
    if source.is_file():
        return load_suite(source)
    if (source / 'metadata.yaml').is_file():
        return Suite(source.name, (entry_from_bag(source),), source)
    if (source / SUITE_FILE).is_file():
        return load_suite(source / SUITE_FILE)
    return suite_from_bag_directory(source)


def check_bags(suite: Suite) -> None:
    """SuiteError naming the scenario whose bag changed since it was written (episode.json's
    sizes and digests) or whose messages are cut off or corrupt, as ``replay`` refuses it:
    nothing re-runs a map that is not the one recorded."""
    from sessgan_evolver.bag_reading import check_bag_complete, verify_bag_files

    checked: set[Path] = set()
    for entry in suite.entries:
        if entry.bag.resolve() in checked:  # scenarios may share a bag
            continue
        try:
            verify_bag_files(entry.bag)  # a bag older than the digests: nothing to check
            check_bag_complete(entry.bag)
        except BagReadError as err:
            raise SuiteError(f'scenario {entry.name}: {err}') from err
        checked.add(entry.bag.resolve())


def suite_document(name: str, bags: Sequence[Path], directory: Path,
                   metadata: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The YAML document of a suite of ``bags`` for a file in ``directory`` (bag paths
    relative to it)."""
    entries = []
    names = unique_names(Path(bag).name for bag in bags)
    for bag, entry_name in zip(bags, names):
        entry = entry_from_bag(Path(bag), entry_name)
        metrics = entry.episode.get('metrics') or {}
        # Relative to the suite file (with '..' where needed), so the file and its bags can
        # be moved or committed together.
        bag_text = Path(os.path.relpath(Path(bag).resolve(), directory.resolve())).as_posix()
        entries.append({
            'name': entry_name, 'bag': bag_text, 'scenario': entry.scenario,
            'environment_id': entry.environment_id,
            'seed': int(entry.episode.get('episode_seed', entry.episode.get('seed', 0))),
            'controller': str(entry.episode.get('controller', '')),
            'expected': {'outcome': str(metrics.get('outcome', '')),
                         'fault_collisions': int(metrics.get('fault_collisions', 0) or 0)},
        })
    return {'format': SUITE_FORMAT, 'name': name, **dict(metadata or {}), 'scenarios': entries}


def write_suite_file(path: Path, name: str, bags: Sequence[Path],
                     metadata: Mapping[str, Any] | None = None) -> Path:
    """Write the suite of ``bags`` to ``path`` atomically (nothing when ``bags`` is empty:
    an empty suite is refused by :func:`load_suite`); returns ``path``."""
    path = Path(path)
    if not bags:
        return path
    from sessgan_controllers.registry import CONTROLLERS

    document = suite_document(name, list(bags), path.parent, metadata)
    # Bags of a stack that is not a built-in controller re-run only beside that stack.
    external = any(entry['controller'] and entry['controller'] not in CONTROLLERS
                   for entry in document['scenarios'])
    text = ('# Regression suite: ros2 run sessgan_evolver suite ' + path.name
            + (' --external' if external else '') + '\n'
            + yaml.safe_dump(document, sort_keys=False))
    atomic_write_bytes(path, text.encode('utf-8'))
    return path


def suite_line(suite: Path, external: bool) -> str:
    """Where a command's regression suite is and the command that re-runs it (an external
    stack's bags name no built-in controller: the re-run needs --external too)."""
    return (f'regression suite: {suite} (re-run: ros2 run sessgan_evolver suite {suite}'
            f'{" --external" if external else ""})')


def write_suite_of_bags_below(path: Path, name: str, directory: Path,
                              metadata: Mapping[str, Any] | None = None) -> Path | None:
    """Write the suite of every failure bag below ``directory`` to ``path`` (what ``campaign``,
    ``compare`` and ``evaluate`` found); None, and nothing written, when there is none."""
    bags = bags_below(directory)
    if not bags:
        return None
    return write_suite_file(path, name, bags, metadata)


# ---- judging ----------------------------------------------------------------------------


def classify(metrics: Mapping[str, Any]) -> AttemptKind:
    """Whether an episode passes, fails (a fault of the robot under test in a valid test:
    sessgan_sim.metrics.is_controller_failure) or is a harness outcome (no result)."""
    outcome = str(metrics.get('outcome') or '')
    if outcome in HARNESS_OUTCOMES or not outcome:
        return AttemptKind.HARNESS
    if not metrics.get('feasible', True):
        # The recorded map was a valid test; not feasible now is the harness's doing.
        return AttemptKind.HARNESS
    if int(metrics.get('fault_collisions', 0) or 0) > 0 or outcome in FAILURE_OUTCOMES:
        return AttemptKind.FAIL
    return AttemptKind.PASS


@dataclass
class Attempt:
    """One episode of a scenario."""

    kind: AttemptKind
    metrics: dict[str, Any]
    bag_path: str = ''

    @property
    def outcome(self) -> str:
        return str(self.metrics.get('outcome') or '')

    @property
    def detail(self) -> str:
        return str(self.metrics.get('detail') or '')

    def describe(self) -> str:
        text = self.outcome or 'no outcome'
        faults = int(self.metrics.get('fault_collisions', 0) or 0)
        if faults:
            text += f', {faults} fault collision(s)'
        return f'{self.kind.value}: {text}' + (f' ({self.detail})' if self.detail else '')


@dataclass
class ScenarioProgress:
    """The attempts of one scenario so far and what it still needs.

    ``results_wanted``: results (pass or fail) that make the verdict (1 when exact, else
    1 + retries); ``harness_tries``: harness outcomes in a row after which it is an error.
    """

    entry: SuiteEntry
    results_wanted: int
    harness_tries: int
    attempts: list[Attempt] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.results_wanted < 1:
            raise SuiteError('a scenario needs at least one result')
        if self.harness_tries < 1:
            raise SuiteError('harness tries must be >= 1')

    @property
    def results(self) -> list[Attempt]:
        return [a for a in self.attempts if a.kind is not AttemptKind.HARNESS]

    @property
    def harness_in_a_row(self) -> int:
        count = 0
        for attempt in reversed(self.attempts):
            if attempt.kind is not AttemptKind.HARNESS:
                break
            count += 1
        return count

    @property
    def overloaded_in_a_row(self) -> int:
        """Overloaded attempts (clocked: the stack could not keep pace) among the harness
        outcomes in a row at the end: how much slower --adaptive-rtf runs the next one."""
        return sum(1 for attempt in self.attempts[len(self.attempts) - self.harness_in_a_row:]
                   if attempt.outcome == 'overloaded')

    @property
    def done(self) -> bool:
        return (len(self.results) >= self.results_wanted
                or self.harness_in_a_row >= self.harness_tries)

    def needed(self) -> int:
        """Attempts to start now (0 when done); a harness outcome is re-run one at a time."""
        if self.done:
            return 0
        if self.attempts and self.attempts[-1].kind is AttemptKind.HARNESS:
            return 1
        return self.results_wanted - len(self.results)

    def add(self, attempt: Attempt) -> None:
        self.attempts.append(attempt)

    @property
    def verdict(self) -> Verdict:
        results = self.results
        if not self.done:
            return Verdict.NOT_RUN
        if len(results) < self.results_wanted:
            return Verdict.ERROR
        kinds = {attempt.kind for attempt in results}
        if kinds == {AttemptKind.PASS}:
            return Verdict.PASS
        if kinds == {AttemptKind.FAIL}:
            return Verdict.FAIL
        return Verdict.FLAKY

    def representative(self) -> Attempt | None:
        """The attempt whose metrics a report shows: the last failing result for fail and
        flaky, else the last result, else the last attempt."""
        results = self.results
        failing = [a for a in results if a.kind is AttemptKind.FAIL]
        chosen = failing or results or self.attempts
        return chosen[-1] if chosen else None

    def detail(self) -> str:
        verdict = self.verdict
        results = self.results
        if verdict is Verdict.ERROR:
            last = self.attempts[-1]
            return (f'harness error: no result in {self.harness_in_a_row} attempt(s), last '
                    f'{last.outcome}' + (f' ({last.detail})' if last.detail else ''))
        if verdict is Verdict.NOT_RUN:
            return 'not run (interrupted)'
        failing = sum(1 for a in results if a.kind is AttemptKind.FAIL)
        rep = self.representative()
        head = f'{failing} of {len(results)} result(s) failed'
        if rep is not None:
            head += f'; {rep.describe()}'
        if self.entry.expected_outcome:
            head += f'; recorded: {self.entry.expected_outcome}'
            if self.entry.expected_fault_collisions:
                head += f', {self.entry.expected_fault_collisions} fault collision(s)'
        return head


# ---- reports ----------------------------------------------------------------------------


def _number(value: Any, short: bool = False) -> str:
    """A metric as text: bools as 0/1, floats in full (``short``: 4 significant digits),
    non-finite and missing values empty."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return ''
        return f'{value:.4g}' if short else repr(value)
    return '' if value is None else str(value)


def properties_of(progress: ScenarioProgress) -> dict[str, str]:
    """The scenario's JUnit properties: verdict, attempts, the representative attempt's
    metrics and bag, what it was recorded with."""
    rep = progress.representative()
    props = {
        'verdict': progress.verdict.value,
        'scenario': progress.entry.scenario,
        'environment_id': progress.entry.environment_id,
        'source_bag': str(progress.entry.bag),
        'recorded_outcome': progress.entry.expected_outcome,
        'attempts': str(len(progress.attempts)),
        'attempt_outcomes': ' '.join(f'{a.kind.value}:{a.outcome or "-"}'
                                     for a in progress.attempts),
    }
    if rep is not None:
        props['outcome'] = rep.outcome
        # The path length is EpisodeMetrics' distance_travelled.
        values = {**rep.metrics, 'path_length': rep.metrics.get('distance_travelled')}
        for name in NUMERIC_PROPERTIES:
            if name in rep.metrics or (name == 'path_length' and 'distance_travelled' in values):
                props[name] = _number(values[name])
        props['bag'] = rep.bag_path
    return props


def junit_xml(suite: str, progresses: Sequence[ScenarioProgress], elapsed: float,
              interrupted: bool = False) -> str:
    """JUnit XML: one testcase per scenario; fail -> <failure>, harness error -> <error>,
    not run -> <skipped>, flaky -> passing with a <flakyFailure> per failed attempt (the
    Maven Surefire rerun convention that Jenkins and GitLab read)."""
    counts = {verdict: sum(1 for p in progresses if p.verdict is verdict) for verdict in Verdict}
    root = ElementTree.Element('testsuites', {
        'name': suite, 'tests': str(len(progresses)), 'failures': str(counts[Verdict.FAIL]),
        'errors': str(counts[Verdict.ERROR]), 'skipped': str(counts[Verdict.NOT_RUN]),
        'time': f'{elapsed:.3f}'})
    testsuite = ElementTree.SubElement(root, 'testsuite', {
        'name': suite, 'tests': str(len(progresses)), 'failures': str(counts[Verdict.FAIL]),
        'errors': str(counts[Verdict.ERROR]), 'skipped': str(counts[Verdict.NOT_RUN]),
        'time': f'{elapsed:.3f}'})
    if interrupted:
        suite_props = ElementTree.SubElement(testsuite, 'properties')
        ElementTree.SubElement(suite_props, 'property', {'name': 'interrupted', 'value': '1'})
    for progress in progresses:
        wall = sum(float(a.metrics.get('wall_time') or 0.0) for a in progress.attempts)
        case = ElementTree.SubElement(testsuite, 'testcase', {
            'classname': f'sessgan.{progress.entry.scenario or "scenario"}',
            'name': progress.entry.name, 'time': f'{wall:.3f}'})
        props = ElementTree.SubElement(case, 'properties')
        for name, value in properties_of(progress).items():
            ElementTree.SubElement(props, 'property', {'name': name, 'value': value})
        verdict, detail = progress.verdict, progress.detail()
        if verdict is Verdict.FAIL:
            ElementTree.SubElement(case, 'failure', {'message': detail,
                                                     'type': 'controller_failure'}).text = detail
        elif verdict is Verdict.ERROR:
            ElementTree.SubElement(case, 'error', {'message': detail,
                                                   'type': 'harness_error'}).text = detail
        elif verdict is Verdict.NOT_RUN:
            ElementTree.SubElement(case, 'skipped', {'message': detail})
        elif verdict is Verdict.FLAKY:
            for attempt in progress.results:
                if attempt.kind is AttemptKind.FAIL:
                    ElementTree.SubElement(case, 'flakyFailure', {
                        'message': attempt.describe(), 'type': 'controller_failure'})
        ElementTree.SubElement(case, 'system-out').text = '\n'.join(
            f'attempt {number}: {attempt.describe()}'
            + (f' bag {attempt.bag_path}' if attempt.bag_path else '')
            for number, attempt in enumerate(progress.attempts, start=1)) or detail
    ElementTree.indent(root)
    return ElementTree.tostring(root, encoding='unicode', xml_declaration=True) + '\n'


CSV_COLUMNS = ('name', 'verdict', 'scenario', 'environment_id', 'attempts', 'attempt_outcomes',
               'recorded_outcome', 'outcome', *NUMERIC_PROPERTIES, 'bag', 'source_bag', 'detail')


def csv_text(progresses: Sequence[ScenarioProgress]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=CSV_COLUMNS, extrasaction='ignore',
                            lineterminator='\n')
    writer.writeheader()
    for progress in progresses:
        row = {'name': progress.entry.name, 'detail': progress.detail(),
               **properties_of(progress)}
        writer.writerow(row)
    return out.getvalue()


def markdown_summary(suite: str, progresses: Sequence[ScenarioProgress], elapsed: float,
                     command: str = '', interrupted: bool = False,
                     notes: Sequence[str] = ()) -> str:
    """``notes``: how the episodes ran (each external worker's mode and pace, the modes the
    scenarios were recorded in), a line each."""
    counts = {verdict: sum(1 for p in progresses if p.verdict is verdict) for verdict in Verdict}
    lines = [f'# Regression suite: {suite}', '']
    if command:
        lines += [f'Command: `{command}`', '']
    if notes:
        lines += [*(f'* {note}' for note in notes), '']
    if interrupted:
        lines += ['**Interrupted**: scenarios without a verdict are marked not_run.', '']
    lines += [f'{len(progresses)} scenarios in {elapsed:.1f} s: '
              + ', '.join(f'{counts[v]} {v.value}' for v in Verdict if counts[v]), '',
              '| scenario | verdict | attempts | outcome | fault collisions | time to goal s '
              '| path ratio | min clearance m | bag |',
              '|---|---|---|---|---|---|---|---|---|']
    for progress in progresses:
        rep = progress.representative()
        metrics = rep.metrics if rep else {}
        lines.append('| ' + ' | '.join((
            progress.entry.name, progress.verdict.value,
            ' '.join(a.kind.value for a in progress.attempts) or '-',
            rep.outcome if rep else '-', _number(metrics.get('fault_collisions')),
            _number(metrics.get('time_to_goal'), True),
            _number(metrics.get('path_length_ratio'), True),
            _number(metrics.get('min_clearance'), True), (rep.bag_path if rep else '') or '-'))
            + ' |')
    return '\n'.join(lines) + '\n'


@dataclass(frozen=True)
class SuiteOutputs:
    junit: Path
    markdown: Path
    csv: Path


def write_outputs(directory: Path, suite: str, progresses: Sequence[ScenarioProgress],
                  elapsed: float, command: str = '', interrupted: bool = False,
                  notes: Sequence[str] = ()) -> SuiteOutputs:
    """junit.xml, summary.md and scenarios.csv in ``directory``, each written atomically."""
    directory = Path(directory)
    outputs = SuiteOutputs(directory / 'junit.xml', directory / 'summary.md',
                           directory / 'scenarios.csv')
    atomic_write_bytes(outputs.junit, junit_xml(suite, progresses, elapsed,
                                                interrupted).encode('utf-8'))
    atomic_write_bytes(outputs.markdown, markdown_summary(suite, progresses, elapsed, command,
                                                          interrupted, notes).encode('utf-8'))
    atomic_write_bytes(outputs.csv, csv_text(progresses).encode('utf-8'))
    return outputs


EXIT_PASSED, EXIT_FAILED, EXIT_USAGE, EXIT_HARNESS = 0, 1, 2, 3
EXIT_INTERRUPTED = 130


def exit_code(progresses: Sequence[ScenarioProgress], fail_on_flaky: bool = False,
              interrupted: bool = False) -> int:
    """130 when interrupted (the run is incomplete, whatever it saw: CI tells a cancelled
    job from a regression), else 1 when a scenario failed (or was flaky with
    ``fail_on_flaky``), else 3 when one is a harness error, else 0."""
    verdicts = {p.verdict for p in progresses}
    if interrupted:
        return EXIT_INTERRUPTED
    if Verdict.FAIL in verdicts or (fail_on_flaky and Verdict.FLAKY in verdicts):
        return EXIT_FAILED
    if Verdict.ERROR in verdicts:
        return EXIT_HARNESS
    return EXIT_PASSED
