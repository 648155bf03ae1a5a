"""`ros2 run sessgan_evolver campaign`: evolve a generator population against a robot.

Starts (or, with --external / an existing graph, attaches to) the generator node, N simulator
workers under /w0, /w1, ... and a built-in controller per worker, each its own process; runs the
campaign over ROS (the generator's ``generate_environments`` service, every discovered
``evaluate`` action server in parallel); writes runs/<run>/ and bags/<run>/; stops every process
it started on exit, Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from sessgan_core.atomic_files import lock_folder
from sessgan_core.config_cli import add_config_arguments, build_parser, config_from_namespace
from sessgan_core.errors import SessganCoreError
from sessgan_core.ros_spin import INTERRUPTED_STATUS, init_rclpy, run_command
from sessgan_core.scenarios import get_scenario
from sessgan_evolver.campaign import (
    DEFAULT_METHOD,
    SESSGAN_METHOD,
    Campaign,
    CampaignConfig,
)
from sessgan_evolver.errors import HarnessFailureError, RunStoreError, SessganEvolverError
from sessgan_evolver.method_campaign import MethodCampaign
from sessgan_evolver.process_supervisor import (
    ChildProcess,
    ProcessSupervisor,
    WorkerPool,
    controller_placements,
    worker_cores,
)
from sessgan_evolver.ros_evaluator import GENERATOR_NAMESPACE, RosEvaluator
from sessgan_evolver.search_methods import screening_effort
from sessgan_gen.errors import SessganGenError


@dataclass
class RunPlace:
    """Where a campaign's run goes and whether it resumes: options, not settings (kept in
    config.json beside them, :func:`invocation_of`)."""

    run: str = ''
    """Run name (default: <scenario>-seed<seed>)."""
    runs_root: Path = Path('runs')
    """Directory of the run directories."""
    bags_root: Path = Path('bags')
    """Directory of the failure bag directories."""
    resume: bool = False
    """Continue a killed run from its last completed generation."""
    worker_bags: Literal['keep', 'remove'] = 'keep'
    """With --external: after a failure bag is copied (verified) into <bags-root>/<run>/, keep
    the worker's copy or remove it."""


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    return campaign_parser().parse_args(argv)


def campaign_parser() -> argparse.ArgumentParser:
    """The options: one per CampaignConfig field (its nested FitnessConfig as --fitness-...),
    plus one per RunPlace field."""
    parser = build_parser(CampaignConfig, prog='ros2 run sessgan_evolver campaign',
                          description=__doc__ or '')
    add_config_arguments(parser, RunPlace)
    # The command's default method is the best measured; a CampaignConfig in code: sessgan.
    parser.set_defaults(method=DEFAULT_METHOD)
    return parser


def config_from_args(args: argparse.Namespace) -> CampaignConfig:
    return config_from_namespace(CampaignConfig, args)


def invocation_of(args: argparse.Namespace, argv: Sequence[str]) -> dict[str, Any]:
    """The options that are not settings (where the run goes, resume) and the command line,
    kept in config.json beside the settings."""
    return {'run': args.run, 'runs_root': str(args.runs_root),
            'bags_root': str(args.bags_root), 'resume': bool(args.resume),
            'worker_bags': args.worker_bags,
            'command_line': ['ros2', 'run', 'sessgan_evolver', 'campaign', *argv]}


# ---- processes ---------------------------------------------------------------------------


def start_graph(supervisor: ProcessSupervisor, pool: WorkerPool, config: CampaignConfig,
                controller: str, generator_running: bool,
                bags_root: Path = Path('bags')) -> ChildProcess | None:
    """Start the generator (unless one runs) and, without ``config.external``, a simulator +
    controller pair per worker (writing failure bags under ``bags_root``); returns the
    generator process started, if any."""
    generator = None
    if not generator_running:
        # No checkpoint parameter: the campaign sends every member's weights itself.
        generator = supervisor.start('generator', [
            'ros2', 'run', 'sessgan_gen', 'generator', '--ros-args',
            '-r', f'__ns:={GENERATOR_NAMESPACE}', '-p', f'scenario:={config.scenario}',
            '-p', 'rate:=0.0', '-p', f'mission_stations:={config.mission_stations}',
            '-p', f'station_dwell_time:={float(config.station_dwell_time)}',
            '-p', f'robots:={config.robots}'])
    if config.external:
        return generator
    from sessgan_controllers.registry import CONTROLLERS

    spec = CONTROLLERS.get(controller)
    scenario_robot = get_scenario(config.scenario).robot
    robot = robot_of(controller, config.scenario)
    robot_args = spec.node_arguments(robot) if spec else []
    # The simulators host the controller's own robot where it stands in for the scenario's
    # (the tricycle of tricycle_nearness_diagram).
    simulator_args = robot_args or (['-p', f'robot:={robot}'] if robot != scenario_robot else [])
    for worker, core in enumerate(worker_cores(config.workers)):
        namespace = f'/w{worker}'
        ros_args = ['--ros-args', '-r', f'__ns:={namespace}']
        pool.start_pair(
            namespace,
            (f'simulator_w{worker}', [
                'ros2', 'run', 'sessgan_sim', 'simulator', *ros_args,
                '-p', f'mode:={config.mode}', '-p', f'bag_storage:={config.bag_storage}',
                '-p', f'bags_root:={Path(bags_root).resolve()}', *simulator_args]),
            # A fleet's robots each get a controller of their own (/w0/r0, /w0/r1, ...).
            *((f'{controller}_{robot_namespace[1:].replace("/", "_")}', [
                'ros2', 'run', 'sessgan_controllers', controller, '--ros-args', *placement,
                '-p', 'use_sim_time:=true', *robot_args])
              for robot_namespace, placement in controller_placements(namespace,
                                                                     config.robots)),
            core=core, batch=True)
    return generator


def robot_of(controller: str, scenario: str) -> str:
    """The robot the simulators host: the scenario's, or the one a built-in controller
    stands in with (the tricycle of tricycle_nearness_diagram)."""
    from sessgan_controllers.registry import CONTROLLERS

    spec = CONTROLLERS.get(controller)
    scenario_robot = get_scenario(scenario).robot
    return spec.robot_in(scenario_robot) if spec else scenario_robot


def main(argv: Sequence[str] | None = None) -> int:
    """Exit status: 0 done, 1 failed (a --resume hint when the run can go on), 2 bad
    settings (nothing written), 130 interrupted (SIGINT or SIGTERM; the --resume hint)."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    return run_command(lambda: run_campaign(arguments), 'interrupted')


def run_campaign(argv: list[str]) -> int:
    args = parse_args(argv)
    try:
        config = config_from_args(args)
        config.validate()
    except (SessganEvolverError, SessganCoreError, SessganGenError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    run_name = args.run or f'{config.scenario}-seed{config.seed}'
    controller = config.controller or get_scenario(config.scenario).controller
    if config.external:
        controller = config.controller or 'external'

    resume = resume_command(argv, run_name)

    def log(message: str) -> None:
        print(f'[campaign] {message}', file=sys.stderr, flush=True)

    try:
        campaign = make_campaign(config, run_name, args.runs_root, args.bags_root, log,
                                 invocation_of(args, argv))
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    except OSError as err:  # the run directory cannot be made
        print(f'error: {err}', file=sys.stderr)
        return 1
    # Held until the campaign ends: two campaigns in one run would interleave their rows.
    held = lock_folder(campaign.store.run_dir, RUN_LOCK)
    if held is None:
        print(f'error: run {run_name!r} is in use by another campaign ({campaign.store.run_dir})'
              ': give this one another --run, or wait for that one to end', file=sys.stderr)
        return 2
    try:  # before any process starts: a resume with other settings than the run's
        campaign.store.check_config(campaign.config.to_dict(), config.seed)
    except RunStoreError as err:
        held.close()
        print(f'error: {err}', file=sys.stderr)
        return 2

    # SIGINT and SIGTERM raise KeyboardInterrupt (run_command), so the children are stopped;
    # caught here, so a signal while the graph stops or the report is written gives the hint too.
    try:
        if config.in_process:
            return run_in_process(campaign, config, controller, resume, args.resume, log)
        return run_with_ros(campaign, config, controller, resume, args.resume, log,
                            args.worker_bags)
    except KeyboardInterrupt:
        log('interrupted: stopping every process this campaign started (continue later with: '
            f'{resume})')
        return INTERRUPTED_STATUS
    finally:
        held.close()


RUN_LOCK = '.campaign.lock'
"""The file in a run folder a running campaign holds (sessgan_core.atomic_files.lock_folder)."""


def resume_command(argv: Sequence[str], run_name: str) -> str:
    """The command that continues this run: the same options, with --resume and --run."""
    extra = [] if '--resume' in argv else ['--resume']
    if not any(arg == '--run' or arg.startswith('--run=') for arg in argv):
        extra += ['--run', run_name]
    return shlex.join(['ros2', 'run', 'sessgan_evolver', 'campaign', *argv, *extra])


def run_with_ros(campaign: Campaign | MethodCampaign, config: CampaignConfig, controller: str,
                 resume_hint: str, resume: bool, log: Callable[[str], None],
                 worker_bags: str = 'keep') -> int:
    """The campaign on the ROS graph: its generator and workers (or yours, --external);
    ``resume_hint``: the command that continues it."""
    run_name = campaign.store.run_name
    import rclpy
    init_rclpy(['--ros-args'])
    node = rclpy.create_node('sessgan_evolver')
    supervisor = ProcessSupervisor(campaign.store.run_dir / 'logs')
    try:
        # Goals name bags/<run>/ relative to the simulators' bags root (they write nowhere else).
        evaluator = RosEvaluator(node, config, Path(run_name), controller, supervisor, log)
        if config.external:  # workers elsewhere: their failure bags are copied to bags/<run>/
            evaluator.collect_into = campaign.bags_dir
            evaluator.remove_collected = worker_bags == 'remove'
        evaluator.expected_robot = robot_of(controller, config.scenario)
        # Ask/tell methods make their maps in this process: no generator node.
        needs_generator = config.method == SESSGAN_METHOD
        generator_running = (not needs_generator
                             or evaluator.generator.wait_for_service(timeout_sec=1.0))
        if not config.external:
            evaluator.allowed = {f'/w{i}/evaluate' for i in range(config.workers)}
            evaluator.wait_until_absent(sorted(evaluator.allowed), timeout=15.0)
        evaluator.generator_process = start_graph(
            supervisor, evaluator.pool, config, controller, generator_running,
            campaign.bags_dir.parent)
        log(f'run {run_name}: {plan_of(campaign.config)}, scenario {config.scenario}, '
            f'controller {controller}, ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}')
        if needs_generator:
            evaluator.wait_for_generator(timeout=120.0)
        evaluator.wait_for_workers(1 if config.external else config.workers, timeout=120.0)
        cpu = time.process_time()
        result = campaign.run(evaluator, resume=resume)
        evaluator.overhead.cpu = time.process_time() - cpu
        log(evaluator.overhead.summary())
    except (HarnessFailureError, OSError) as err:
        # OSError: the run directory cannot be written (a full disk): nothing more can be.
        log(f'error: {err}\nstopped; continue later with: {resume_hint}')
        return 1
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        log(f'error: {err}')
        return 1
    finally:
        supervisor.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()
        remove_if_empty(campaign.store.run_dir)  # e.g. no worker answered
    return report_result(result, log, config.external)


def remove_if_empty(directory: Path) -> None:
    """Remove ``directory`` when nothing but empty folders and the campaign's lock file is
    below it (the run directory, checkpoints/ and logs/ are made up front): a campaign that
    wrote nothing leaves nothing."""
    if directory.is_dir() and all(path.is_dir() or path.name == RUN_LOCK
                                  for path in directory.rglob('*')):
        shutil.rmtree(directory, ignore_errors=True)


def run_in_process(campaign: Campaign | MethodCampaign, config: CampaignConfig,
                   controller: str, resume_hint: str, resume: bool,
                   log: Callable[[str], None]) -> int:
    """The campaign with sessgan_evolver.in_process's evaluator: no ROS at all;
    ``resume_hint``: the command that continues it."""
    run_name = campaign.store.run_name
    from sessgan_evolver.in_process import InProcessEvaluator

    log(f'run {run_name}: {plan_of(campaign.config)}, scenario {config.scenario}, controller '
        f'{controller}, in process')
    try:
        with InProcessEvaluator(
                config.scenario, controller, config.time_limit,
                record_directory=campaign.bags_dir if config.record_failures else None,
                bag_storage=config.bag_storage, mission=config.mission(),
                fleet=config.fleet(), size=(config.height, config.width),
                harness_tries=config.harness_tries, log=log) as evaluator:
            result = campaign.run(evaluator, resume=resume)
    except (HarnessFailureError, OSError) as err:
        log(f'error: {err}\nstopped; continue later with: {resume_hint}')
        return 1
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        log(f'error: {err}')
        return 1
    return report_result(result, log)


def make_campaign(config: CampaignConfig, run_name: str, runs_root: Path, bags_root: Path,
                  log: Callable[[str], None], invocation: dict[str, Any]
                  ) -> Campaign | MethodCampaign:
    """The weight evolution for sessgan, else the ask/tell method's campaign."""
    if config.method == SESSGAN_METHOD:
        return Campaign(config, run_name, runs_root, bags_root, log, invocation=invocation)
    return MethodCampaign(config, run_name, runs_root, bags_root, log, invocation=invocation)


def plan_of(config: CampaignConfig) -> str:
    """What the campaign will run, for its first log line."""
    if config.method == SESSGAN_METHOD:
        return (f'sessgan, {config.generations} generations x {config.population} members x '
                f'{config.maps_per_member} maps')
    if config.method == 'screened':
        effort = screening_effort(config.screening_effort, config.external, config.scenario)
        exploration = (f', exploration {config.exploration:g}' if config.exploration else '')
        return (f'screened (screening effort {effort}{exploration}), '
                f'{config.resolved_budget()} episodes')
    return f'{config.method}, {config.resolved_budget()} episodes'


def report_result(result: Any, log: Callable[[str], None], external: bool = False) -> int:
    """Print where the results are; the exit status: 1 when no map of the whole campaign was a
    valid test (its figures measure nothing), else 0. ``external``: the robot ran in its own
    processes, so the suite's re-run needs --external too (its bags name no built-in
    controller)."""
    first, last = result.generations[0], result.generations[-1]
    episodes = int(last.get('episodes_so_far') or 0)
    failures = int(last.get('valid_failures_so_far') or 0)
    faults = int(last.get('distinct_faults_so_far') or 0)
    unplaced = int(last.get('unplaced_failures_so_far') or 0)
    per = 1.0 / episodes if episodes else 0.0
    reruns = sum(int(row.get('harness_reruns') or 0) for row in result.generations)
    log(f'done in {result.wall_time / 60:.1f} min: {failures} valid failures '
        f'({failures * per:.3f}/episode), {faults} distinct faults ({faults * per:.3f}/episode)'
        + (f', {last["fault_situations_so_far"]} fault situations'
           if 'fault_situations_so_far' in last else '')
        + (f' + {unplaced} unplaced' if unplaced else '') + f' in {episodes} episodes; '
        f'fault risk {first.get("mean_fault_risk_score") or 0:.3f} (generation 0) -> '
        f'{last.get("mean_fault_risk_score") or 0:.3f} (generation {last["generation"]}); '
        f'risk {first.get("mean_risk_score") or 0:.3f} -> '
        f'{last.get("mean_risk_score") or 0:.3f}'
        + (f'; harness re-runs {reruns} (run again, not results)' if reruns else ''))
    print(f'report: {result.report_path}')
    if result.bags_dir.is_dir() and any(result.bags_dir.iterdir()):
        print(f'failure bags: {result.bags_dir}')
    else:
        lost = sum(int(row.get('lost_bags') or 0) for row in result.generations)
        print('failure bags: none' + (f' ({lost} were lost: see bag_error in '
                                      'metrics_episodes.csv)' if lost else
                                      ' (no failure was recorded)'))
    from sessgan_evolver.regression_suite import SUITE_FILE, suite_line, write_suite_of_bags_below

    suite = write_suite_of_bags_below(result.run_dir / SUITE_FILE, result.run_dir.name,
                                      result.bags_dir, {'source': 'campaign failure bags'})
    if suite is not None:
        print(suite_line(suite, external))
    if not any(row.get('feasible_fraction') for row in result.generations):
        log('error: no map of this campaign was a valid test (none held a route for the '
            'robot), so it could find no fault: check the map the generator learned')
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
