"""`ros2 run sessgan_evolver suite <suite.yaml | bags dir | bag>`: a regression suite for CI.

Re-runs every recorded scenario (a suite file written by ``campaign`` or ``evaluate``, a
directory of failure bags, or one bag) against the robot under test and writes
<output-dir>/junit.xml (one testcase per scenario: verdict, detail, metrics as properties, the
new bag), summary.md and scenarios.csv.

By default each scenario runs in this process with a built-in controller (the recorded one,
or --controller) in lockstep: exact, so one result is its verdict. With --external the
episodes go to the simulators already running under /w0, /w1, ... (each beside your
controller; every discovered ``evaluate`` action server is used, in parallel): their timing
depends on the machine, so each scenario runs 1 + --retries times and is pass, fail or flaky
(mixed). A harness outcome (controller_unresponsive, cancelled, a map the simulator could not
build) is no result: it is run again, and after --harness-tries in a row the scenario is a
harness error (JUnit <error>), never a pass or a fail.

Exit codes: 130 interrupted (Ctrl-C, SIGTERM: what ran is reported, the rest is marked
not_run); else 0 every scenario passed (flaky ones too, unless --fail-on-flaky); 1 a scenario
failed; 2 bad input (a missing, changed or cut-off bag, a bag of another scenario, malformed
YAML, an empty suite, an output folder that is a file or that another run holds: nothing is
run); 3 a harness error and no failure.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import os
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Literal

from sessgan_core.atomic_files import lock_folder
from sessgan_core.config_cli import cli, parse_valid_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.progress import ProgressPrinter
from sessgan_core.ros_spin import init_rclpy, run_command
from sessgan_core.validation import ros_namespace
from sessgan_evolver.errors import SessganEvolverError, SuiteError
from sessgan_evolver.regression_suite import (
    EXIT_HARNESS,
    EXIT_USAGE,
    Attempt,
    AttemptKind,
    ScenarioProgress,
    Suite,
    SuiteEntry,
    Verdict,
    check_bags,
    classify,
    exit_code,
    load_suite_source,
    unique_names,
    write_outputs,
)
from sessgan_gen.errors import SessganGenError


@dataclass
class SuiteConfig:
    """The ``suite`` command's arguments."""

    source: Path = field(metadata=cli(positional=True))
    """A suite file (YAML), a directory of failure bags, or one bag."""
    output_dir: Path | None = field(default=None, metadata=cli(old=['--output']))
    """Folder for junit.xml, summary.md, scenarios.csv and bags/ (default: runs/suite-<suite
    name>)."""
    controller: str = ''
    """Built-in controller to test (default: each bag's recorded one)."""
    external: bool = False
    """Run the episodes on the simulators already running (every discovered evaluate action
    server, e.g. /w0/evaluate), each beside the controller under test."""
    worker: tuple[str, ...] = field(default=(), metadata=cli(old=['--workers']))
    """--external: only the simulator workers under these namespaces (/w0,/w1; default: every
    one discovered)."""
    retries: int = 0
    """--external: re-runs per scenario beyond the first (verdicts: pass, fail, flaky); in
    process episodes are exact and run once."""
    harness_tries: int = 3
    """Harness outcomes in a row before a scenario is a harness error."""
    adaptive_rtf: bool = False
    """--external, clocked simulators: run an attempt after one that ended overloaded (the
    stack could not keep pace with sim time) at half the real-time factor, halved again on
    each overloaded attempt in a row (down to 1/16)."""
    record: Literal['all', 'failures', 'none'] = 'failures'
    """Bags of the re-runs to keep: all, failures or none (--external: the simulators record
    failures only)."""
    fail_on_flaky: bool = False
    """Exit 1 when a scenario is flaky, too."""
    episode_timeout: float = 0.0
    """--external: wall seconds per episode before it is retried on another worker (default
    0: from the time limit and map size)."""

    def validate(self) -> None:
        if self.retries < 0:
            raise SuiteError(f'--retries must be >= 0, got {self.retries}')
        if self.harness_tries < 1:
            raise SuiteError(f'--harness-tries must be >= 1, got {self.harness_tries}')
        if self.external and self.record == 'all':
            raise SuiteError('--record all needs the in-process runner: external simulators '
                             'record failures only')
        if self.adaptive_rtf and not self.external:
            raise SuiteError('--adaptive-rtf needs --external: in process, episodes run in '
                             'lockstep')
        if self.controller and self.external:
            raise SuiteError('--controller picks a built-in controller; with --external the '
                             'controller is the one running beside each simulator')
        self.worker = tuple(ros_namespace('--worker', name, SuiteError) for name in self.worker)
        from sessgan_evolver.campaign import check_episode_timeout

        try:
            check_episode_timeout(self.episode_timeout)
        except SessganEvolverError as err:
            raise SuiteError(str(err)) from err


def parse_args(argv: Sequence[str]) -> SuiteConfig:
    """The validated arguments; a usage error exits 2 naming the option."""
    return parse_valid_config(SuiteConfig, argv, 'ros2 run sessgan_evolver suite',
                              __doc__ or '', (SuiteError,))


def safe_name(text: str) -> str:
    """``text`` as a directory name a simulator accepts in a record directory (a letter or
    digit, then letters, digits, '.', '_' or '-'; sessgan_sim.bag_recording)."""
    name = ''.join(c if c.isascii() and (c.isalnum() or c in '-_.') else '_' for c in text)
    while '..' in name:
        name = name.replace('..', '.')
    name = name.lstrip('-_.')
    return name[:100] or 'scenario'


# ---- in process --------------------------------------------------------------------------


@dataclass
class PreparedEntry:
    """What runs a scenario in process, built before anything runs (bad input: exit 2)."""

    entry: SuiteEntry
    environment: Any
    seed: int
    controller: str
    settings: Any
    time_limit: float


def prepare_in_process(entry: SuiteEntry, controller: str) -> tuple[PreparedEntry, list[str]]:
    """The environment, seed, controller and lockstep settings of ``entry``; SuiteError
    naming the entry when it cannot be re-simulated in process."""
    from sessgan_controllers.registry import CONTROLLERS
    from sessgan_evolver.replay_cli import bag_environment
    from sessgan_sim.errors import SessganSimError
    from sessgan_sim.simulator_settings import resimulation_settings

    where = f'scenario {entry.name} ({entry.bag})'
    episode = entry.episode
    built_in = ', '.join(sorted(CONTROLLERS))
    if controller and controller not in CONTROLLERS:
        raise SuiteError(f'--controller {controller!r} is not a built-in controller '
                         f'({built_in}): to test your own, run the suite with --external '
                         'beside it')
    name = controller or str(episode.get('controller') or '')
    if name not in CONTROLLERS:
        raise SuiteError(f'{where}: recorded with controller {name!r}, not a built-in one '
                         f'({built_in}): pass --controller or run it with --external beside '
                         'your controller')
    try:
        settings, notes = resimulation_settings(episode)
        environment = bag_environment(entry.bag, dict(episode))
    except (SessganSimError, SessganCoreError, SessganGenError, OSError, KeyError,
            ValueError) as err:
        raise SuiteError(f'{where}: cannot rebuild the recorded episode: {err}') from err
    if settings.mode != 'lockstep':
        settings = dataclasses.replace(settings, mode='lockstep')
        notes = [n for n in notes if 'clocked' not in n]
        notes.append(f'{entry.name}: recorded in clocked mode, re-run in lockstep in process')
    return PreparedEntry(entry, environment, int(episode.get('episode_seed', environment.seed)),
                         name, settings, float(episode.get('time_limit') or 0.0)), notes


class InProcessRunner:
    """Runs scenarios with built-in controllers in this process; one evaluator (one
    simulator) per distinct (scenario, controller, settings, time limit)."""

    def __init__(self, record: str, bags_directory: Path) -> None:
        self.record = record
        self.bags_directory = bags_directory
        self.bag_folders: dict[str, str] = {}
        """Scenario name -> its folder under ``bags_directory`` (:func:`bag_folders`)."""
        self._evaluators: dict[tuple, Any] = {}

    def evaluator(self, prepared: PreparedEntry) -> Any:
        from sessgan_evolver.in_process import InProcessEvaluator

        key = (prepared.environment.scenario, prepared.controller,
               repr(prepared.settings), prepared.time_limit)
        if key not in self._evaluators:
            self._evaluators[key] = InProcessEvaluator(
                prepared.environment.scenario, prepared.controller, prepared.time_limit,
                settings=prepared.settings)
        return self._evaluators[key]

    def run(self, prepared: PreparedEntry, number: int) -> Attempt:
        evaluator = self.evaluator(prepared)
        keep = self.record != 'none'
        run = evaluator.runner.run(prepared.environment, prepared.seed, trace=keep,
                                   keep_scans=keep)
        metrics = dict(run.metrics)
        kind = classify(metrics)
        bag = ''
        if run.trace is not None and (self.record == 'all' or (
                self.record == 'failures' and kind is AttemptKind.FAIL)):
            directory = (self.bags_directory / self.bag_folders[prepared.entry.name]
                         / f'attempt-{number}')
            bag = str(evaluator.write_bag(directory, prepared.environment, prepared.seed, run,
                                          f'suite scenario {prepared.entry.name}'))
            metrics['bag_path'] = bag
        return Attempt(kind, metrics, bag)

    def close(self) -> None:
        for evaluator in self._evaluators.values():
            evaluator.close()
        self._evaluators.clear()


def run_in_process(progresses: list[ScenarioProgress], prepared: list[PreparedEntry],
                   runner: InProcessRunner, report: Callable[[], None]) -> None:
    for progress, entry in zip(progresses, prepared):
        while progress.needed():
            progress.add(runner.run(entry, len(progress.attempts) + 1))
        report()


# ---- external ----------------------------------------------------------------------------


def worker_note(name: str, settings: Any) -> str:
    """How worker ``name`` runs its episodes, from its settings (the ``bags`` service's JSON
    description): a clocked worker's verdicts depend on its pace."""
    if not isinstance(settings, dict) or not settings.get('mode'):
        return f'worker {name}: its settings are unknown'
    pace = (f' at {float(settings["real_time_factor"]):g}x real time'
            if settings['mode'] == 'clocked' and 'real_time_factor' in settings else '')
    return f'worker {name}: {settings["mode"]}{pace}'


def setting_differences(name: str, settings: Any,
                        progresses: Sequence[ScenarioProgress]) -> list[str]:
    """A note for each setting that shapes an episode (a longer stuck window, other agents,
    another lidar) in which worker ``name`` differs from the scenarios' recordings: a
    verdict may change for that reason, not the stack's."""
    from sessgan_sim.simulator_settings import EPISODE_SETTINGS

    if not isinstance(settings, dict):
        return []
    notes = []
    for key in sorted(EPISODE_SETTINGS & settings.keys()):
        recorded: dict[str, int] = {}
        for progress in progresses:
            simulator = progress.entry.episode.get('simulator')
            if isinstance(simulator, dict) and key in simulator \
                    and simulator[key] != settings[key]:
                value = json.dumps(simulator[key], sort_keys=True)
                recorded[value] = recorded.get(value, 0) + 1
        if recorded:
            notes.append(f'WARNING: worker {name} runs with {key} '
                         f'{json.dumps(settings[key], sort_keys=True)}, recorded: '
                         + ', '.join(f'{value} in {count} scenarios'
                                     for value, count in sorted(recorded.items()))
                         + ' (a verdict may change for that, not for the stack)')
    return notes


def recorded_modes(progresses: Sequence[ScenarioProgress]) -> str:
    """'recorded: 5 lockstep, 1 clocked': the modes the scenarios' bags were recorded in."""
    modes: dict[str, int] = {}
    for progress in progresses:
        modes[progress.entry.mode] = modes.get(progress.entry.mode, 0) + 1
    return 'recorded: ' + ', '.join(f'{count} {mode}' for mode, count in sorted(modes.items()))


def run_external(progresses: list[ScenarioProgress], args: SuiteConfig, output: Path,
                 run_bags: str, folders: dict[str, str], report: Callable[[], None],
                 notes: list[str]) -> None:
    """Dispatch every scenario's attempts to the running simulators (the campaign's
    RosEvaluator: parallel, a worker that refuses or stalls gets the job taken away), in
    rounds until every scenario has its verdict. The simulators record failures under
    suite-<output's name>-``run_bags``/<scenario's folder>/attempt-N of their bags root; each
    is copied to <output>/bags/``run_bags``/<scenario's folder>/attempt-N/<environment id>.
    How each worker runs its episodes goes to ``notes``."""
    import rclpy

    from sessgan_evolver.campaign import CampaignConfig, EpisodeJob
    from sessgan_evolver.harness import real_time_factor_scale as slower_pace
    from sessgan_evolver.process_supervisor import ProcessSupervisor
    from sessgan_evolver.replay_cli import bag_environment
    from sessgan_evolver.ros_evaluator import RosEvaluator

    bags = f'suite-{safe_name(output.name)}-{run_bags}'
    environments = []
    for progress in progresses:
        try:
            environments.append(bag_environment(progress.entry.bag, dict(progress.entry.episode)))
        except (SessganCoreError, SessganGenError, OSError, KeyError, ValueError) as err:
            raise SuiteError(f'scenario {progress.entry.name} ({progress.entry.bag}): cannot '
                             f'read the recorded map: {err}') from err
    config = CampaignConfig(scenario=progresses[0].entry.scenario or 'factory',
                            external=True, episode_timeout=args.episode_timeout,
                            record_failures=args.record != 'none')

    class SuiteEvaluator(RosEvaluator):
        rerun_harness_outcomes = False  # every attempt is judged (classify)

        def goal_for(self, job):
            goal = super().goal_for(job)
            episode = progresses[job.member].entry.episode
            goal.time_limit = float(episode.get('time_limit') or 0.0)
            goal.robot = str(episode.get('robot') or '')
            goal.controller = 'external'  # stored with the bag: not the recorded controller
            # A directory per attempt: the simulator names a bag after the environment.
            goal.record_directory = self.bag_places(job)[0] if args.record != 'none' else ''
            return goal

        def bag_places(self, job) -> tuple[str, Path]:
            attempt = f'{folders[progresses[job.member].entry.name]}/attempt-{job.index + 1}'
            return f'{bags}/{attempt}', output / 'bags' / run_bags / attempt

        def real_time_factor_scale(self, job) -> float:
            if not args.adaptive_rtf:
                return 0.0
            return slower_pace(progresses[job.member].overloaded_in_a_row)

    def log(message: str) -> None:
        print(f'[suite] {message}', file=sys.stderr, flush=True)

    init_rclpy(['--ros-args'])  # no rclpy signal handlers: SIGINT is main's (run_command)
    node = rclpy.create_node('sessgan_suite')
    supervisor = ProcessSupervisor(output / 'logs')
    try:
        evaluator = SuiteEvaluator(node, config, Path('suite'), 'external', supervisor, log)
        # Copied here over ROS, verified, as a campaign collects its bags: the report points at
        # the copy, also when the simulators run on other machines.
        evaluator.collect_into = output / 'bags' / run_bags
        if args.worker:
            evaluator.allowed = {f'{name.rstrip("/")}/evaluate' for name in args.worker}
        evaluator.wait_for_workers(1, timeout=60.0)
        from sessgan_evolver.errors import BagCollectionError
        from sessgan_evolver.remote_bags import RemoteBagSource

        for name in evaluator.discover_workers():
            namespace = name.rsplit('/', 1)[0]
            if namespace not in evaluator.bag_sources:  # the one that collects its bags
                evaluator.bag_sources[namespace] = RemoteBagSource(node, namespace,
                                                                   evaluator.spin)
            try:
                description = evaluator.bag_sources[namespace].call_within(5.0)
                settings = json.loads(description.settings)
                notes.append(worker_note(namespace, settings))
                notes += setting_differences(namespace, settings, progresses)
            except (BagCollectionError, ValueError):
                notes.append(worker_note(namespace, None))
        notes.append(recorded_modes(progresses))
        for note in notes:
            log(note)

        def on_result(job, metrics: dict) -> None:
            progress = progresses[job.member]
            progress.add(Attempt(classify(metrics), metrics, str(metrics.get('bag_path') or '')))
            if progress.done:
                report()

        while True:
            jobs = [EpisodeJob(0, index, len(progress.attempts) + k, environments[index],
                               int(progress.entry.episode.get('episode_seed',
                                                              environments[index].seed)))
                    for index, progress in enumerate(progresses)
                    for k in range(progress.needed())]
            if not jobs:
                return
            evaluator.evaluate(jobs, on_result)
    finally:
        supervisor.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()


# ---- the command -------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    # SIGINT and SIGTERM raise KeyboardInterrupt wherever the suite stands (run_command),
    # also when it was started with SIGINT ignored (in the background): running, it stops and
    # reports what ran; preparing, it stops without a traceback. With rclpy's own handlers
    # the context was shut down under the running suite, which ended with an RCLError.
    return run_command(lambda: run_suite(arguments))


_RUNS = itertools.count(1)
"""Suite runs in this process: with the time and the process id, a run's bag folder name."""


def bag_folders(suite: Suite) -> dict[str, str]:
    """Scenario name -> the folder its re-runs' bags go to: the name made safe for a path,
    and distinct ('a/b' and 'a_b' would both be 'a_b')."""
    names = [entry.name for entry in suite.entries]
    return dict(zip(names, unique_names(safe_name(name) for name in names)))


def lock_output(output: Path) -> IO[str]:
    """Hold ``output`` for this run (the open lock file; closing it lets go). SuiteError when
    it is a file, cannot be written, or another suite run holds it: two runs into one folder
    would mix their reports and bags."""
    if output.exists() and not output.is_dir():
        raise SuiteError(f'--output-dir {output} is a file, not a folder')
    try:
        handle = lock_folder(output, '.suite.lock')
    except OSError as err:
        raise SuiteError(f'cannot write to --output-dir {output}: {err}') from err
    if handle is None:
        raise SuiteError(f'another suite run is writing to {output}: give this one another '
                         '--output-dir')
    return handle


def run_suite(arguments: list[str]) -> int:
    args = parse_args(arguments)
    runner = InProcessRunner(args.record, Path())
    with ExitStack() as held:
        held.callback(runner.close)
        return _run_suite(args, arguments, runner, held)


def _run_suite(args: SuiteConfig, arguments: list[str], runner: InProcessRunner,
               held: ExitStack) -> int:
    notes: list[str] = []  # how the episodes run (summary.md): set-up notes, workers' modes
    try:
        suite: Suite = load_suite_source(args.source)
        check_bags(suite)
        prepared: list[PreparedEntry] = []
        if not args.external:
            for entry in suite.entries:
                item, entry_notes = prepare_in_process(entry, args.controller)
                try:  # a controller that cannot drive the recorded robot, ...
                    runner.evaluator(item)
                except SessganEvolverError as err:
                    raise SuiteError(f'scenario {entry.name} ({entry.bag}): {err}') from err
                prepared.append(item)
                for note in entry_notes:
                    print(f'note: {note}', file=sys.stderr)
                notes += entry_notes
        # Resolved: a simulator refuses to write a bag to a path with '..' in it.
        output = (args.output_dir or Path('runs') / f'suite-{safe_name(suite.name)}').resolve()
        held.enter_context(lock_output(output))
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        print(f'error: {err}', file=sys.stderr)
        return EXIT_USAGE
    # This run's bags in a folder of their own: a report never points at another run's bag.
    run_bags = f'{time.strftime("%Y%m%d-%H%M%S")}-{os.getpid()}-{next(_RUNS)}'
    folders = bag_folders(suite)
    runner.bags_directory, runner.bag_folders = output / 'bags' / run_bags, folders
    if not args.external and args.retries:
        print('note: in-process lockstep episodes are exact: each scenario runs once '
              '(--retries applies to --external)', file=sys.stderr)
    wanted = 1 + args.retries if args.external else 1
    progresses = [ScenarioProgress(entry, wanted, args.harness_tries)
                  for entry in suite.entries]
    printer = ProgressPrinter()
    printer.start(f'suite {suite.name}', len(progresses))

    told: set[str] = set()

    def report() -> None:
        done = [p for p in progresses if p.done]
        for progress in done:
            # A harness error's reason, at once: it is no verdict on the controller.
            if progress.verdict is Verdict.ERROR and progress.entry.name not in told:
                told.add(progress.entry.name)
                printer.note(f'{progress.entry.name}: {progress.detail()}')
        counts = {v: sum(1 for p in done if p.verdict is v) for v in Verdict}
        printer.update(len(done), ', '.join(f'{counts[v]} {v.value}' for v in Verdict
                                            if counts[v]))

    started = time.monotonic()
    interrupted = False
    status = None
    try:
        if args.external:
            run_external(progresses, args, output, run_bags, folders, report, notes)
        else:
            run_in_process(progresses, prepared, runner, report)
    except KeyboardInterrupt:
        interrupted = True
        print('\ninterrupted: reporting the scenarios that ran', file=sys.stderr)
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        print(f'error: {err}', file=sys.stderr)
        status = EXIT_HARNESS
    finally:
        runner.close()
        printer.close()
    elapsed = time.monotonic() - started
    command = 'ros2 run sessgan_evolver suite ' + shlex.join(arguments)
    outputs = write_outputs(output, suite.name, progresses, elapsed, command,
                            interrupted or status is not None, notes)
    counts = {v: sum(1 for p in progresses if p.verdict is v) for v in Verdict}
    print(f'{len(progresses)} scenarios: ' + ', '.join(
        f'{counts[v]} {v.value}' for v in Verdict if counts[v]))
    print(f'junit: {outputs.junit}\nsummary: {outputs.markdown}\ncsv: {outputs.csv}')
    code = exit_code(progresses, args.fail_on_flaky, interrupted)
    return status if status is not None and code == 0 else code


if __name__ == '__main__':
    sys.exit(main())
