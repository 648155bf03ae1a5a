"""`ros2 run sessgan_evolver campaign`: evolve a generator population against a robot.

Starts (or, with --external / an existing graph, attaches to) the generator node, N simulator
workers under /w0, /w1, ... and a built-in controller per worker, each its own process; runs the
campaign over ROS (the generator's ``generate_environments`` service, every discovered
``evaluate`` action server in parallel); writes runs/<run>/ and bags/<run>/; stops every process
it started on exit, Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from sessgan_evolver.campaign import Campaign, CampaignConfig, CampaignError, EpisodeJob
from sessgan_evolver.errors import SessganEvolverError
from sessgan_evolver.fitness import FitnessConfig
from sessgan_evolver.process_supervisor import ProcessSupervisor, worker_cores
from sessgan_gen.errors import SessganGenError
from sessgan_gen.scenarios import get_scenario

EVALUATE_TYPE = 'sessgan_interfaces/action/EvaluateEnvironment'
GENERATOR_NAMESPACE = '/sessgan'


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='ros2 run sessgan_evolver campaign', description=__doc__,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    defaults = CampaignConfig()
    docs = field_docs(CampaignConfig)
    for field in dataclasses.fields(CampaignConfig):
        if field.name == 'fitness':
            continue
        flag = '--' + field.name.replace('_', '-')
        default = getattr(defaults, field.name)
        if isinstance(default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default,
                                help=docs.get(field.name, ''))
        else:
            parser.add_argument(flag, type=type(default), default=default,
                                help=docs.get(field.name, ''))
    for field in dataclasses.fields(FitnessConfig):
        parser.add_argument('--fitness-' + field.name.replace('_', '-'), type=float,
                            default=field.default, help=field_docs(FitnessConfig).get(field.name))
    parser.add_argument('--run', default='', help='run name (default: <scenario>-seed<seed>)')
    parser.add_argument('--runs-root', type=Path, default=Path('runs'))
    parser.add_argument('--bags-root', type=Path, default=Path('bags'))
    parser.add_argument('--resume', action='store_true',
                        help='continue a killed run from its last completed generation')
    parser.add_argument('--external', action='store_true',
                        help='start no simulators or controllers: use every evaluate action '
                             'server already running (e.g. your own stack under /w0, /w1)')
    parser.add_argument('--mode', choices=('lockstep', 'clocked'), default='lockstep',
                        help='stepping mode of the simulators this campaign starts')
    parser.add_argument('--in-process', action='store_true',
                        help='no ROS graph: sample and run every episode in this process with '
                             'the built-in controller (lockstep, one episode at a time; '
                             '--workers and --mode are ignored)')
    args = parser.parse_args(argv)
    if args.in_process and args.external:
        parser.error('--in-process runs a built-in controller itself; it cannot use --external '
                     'workers')
    return args


def field_docs(cls) -> dict[str, str]:
    """Attribute docstrings of a dataclass (the string literal after each field)."""
    import ast
    import inspect

    try:
        tree = ast.parse(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    docs, body = {}, tree.body[0].body
    for statement, following in zip(body, body[1:]):
        if (isinstance(statement, ast.AnnAssign) and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)):
            docs[statement.target.id] = ' '.join(str(following.value.value).split())
    return docs


def config_from_args(args: argparse.Namespace) -> CampaignConfig:
    fitness = FitnessConfig(**{f.name: getattr(args, 'fitness_' + f.name)
                               for f in dataclasses.fields(FitnessConfig)})
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(CampaignConfig)
              if f.name != 'fitness'}
    return CampaignConfig(fitness=fitness, **values)


# ---- the ROS evaluator -------------------------------------------------------------------


@dataclass
class Running:
    job: EpisodeJob
    started: float
    send_future: object
    goal_handle: object = None
    result_future: object = None


class RosEvaluator:
    """Generator service + every discovered ``evaluate`` action server, dispatched in parallel.

    A worker that refuses a goal, aborts it, dies or stalls past the episode timeout gets the
    job taken away and retried on another worker; a worker that stalled is quarantined.
    """

    def __init__(self, node, config: CampaignConfig, record_directory: Path, controller: str,
                 supervisor: ProcessSupervisor, log: Callable[[str], None]) -> None:
        from rclpy.action import ActionClient

        from sessgan_interfaces.srv import GenerateEnvironments

        self.node = node
        self.supervisor = supervisor
        self.config = config
        self.record_directory = record_directory
        self.controller = controller
        self.log = log
        self.action_client_class = ActionClient
        self.generator = node.create_client(GenerateEnvironments,
                                            f'{GENERATOR_NAMESPACE}/generate_environments')
        self.clients: dict[str, object] = {}
        self.allowed: set[str] | None = None  # None: every discovered worker (--external)
        self.quarantine: dict[str, float] = {}
        self.max_attempts = 3

    def spin(self, seconds: float = 0.02) -> None:
        import rclpy
        rclpy.spin_once(self.node, timeout_sec=seconds)

    def check_children(self) -> None:
        """Fail fast when a process this campaign started has died."""
        for child in self.supervisor.dead_children():
            raise CampaignError(f'{child.name} exited with status {child.process.returncode}:'
                                f'\n{child.log_tail()}')

    def wait_for_generator(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not self.generator.wait_for_service(timeout_sec=0.5):
            self.check_children()
            if time.monotonic() > deadline:
                raise CampaignError(f'no generator answers at {GENERATOR_NAMESPACE}/'
                                    f'generate_environments after {timeout:.0f} s')

    def evaluate_servers(self) -> list[str]:
        """Names of every ``evaluate`` action server in the graph."""
        from rclpy.action import get_action_names_and_types

        return [name for name, types in get_action_names_and_types(self.node)
                if EVALUATE_TYPE in types]

    def wait_until_absent(self, names: list[str], timeout: float) -> None:
        """Wait for workers of an earlier (killed) campaign to go away before starting ours."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            present = sorted(set(names) & set(self.evaluate_servers()))
            if not present:
                return
            self.spin(0.2)
        raise CampaignError(
            f'{", ".join(present)} already exist in ROS_DOMAIN_ID '
            f'{os.environ.get("ROS_DOMAIN_ID", "0")}: another campaign is running there; stop '
            'it, use --external to share its workers, or pick another ROS_DOMAIN_ID')

    def discover_workers(self) -> list[str]:
        for name in self.evaluate_servers():
            if self.allowed is not None and name not in self.allowed:
                continue
            if name not in self.clients:
                from sessgan_interfaces.action import EvaluateEnvironment
                self.clients[name] = self.action_client_class(
                    self.node, EvaluateEnvironment, name)
                self.log(f'worker found: {name}')
        return sorted(self.clients)

    def wait_for_workers(self, count: int, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ready = [n for n in self.discover_workers() if self.clients[n].server_is_ready()]
            if len(ready) >= count:
                return
            self.check_children()
            self.spin(0.1)
        raise CampaignError(f'only {len(ready)} of {count} simulator workers answered within '
                            f'{timeout:.0f} s')

    def sample(self, weights: bytes, seeds, generation: int, member: int):
        from sessgan_gen.ros_conversion import environment_from_msg
        from sessgan_interfaces.srv import GenerateEnvironments

        request = GenerateEnvironments.Request(
            scenario=self.config.scenario, seeds=[int(s) for s in seeds],
            generation=generation, member=member)
        request.weights = weights
        future = self.generator.call_async(request)
        deadline = time.monotonic() + 120.0
        while not future.done():
            if time.monotonic() > deadline:
                raise CampaignError('the generator did not answer within 120 s')
            self.spin(0.05)
        response = future.result()
        if not response.success:
            raise CampaignError(f'the generator refused member {member}: {response.message}')
        return [environment_from_msg(msg) for msg in response.environments]

    def goal_for(self, job: EpisodeJob):
        from sessgan_gen.ros_conversion import environment_to_msg
        from sessgan_interfaces.action import EvaluateEnvironment

        goal = EvaluateEnvironment.Goal()
        goal.environment = environment_to_msg(job.environment)
        goal.seed = int(job.seed)
        goal.time_limit = float(self.config.time_limit)
        goal.controller = self.controller
        goal.record_directory = str(self.record_directory) if self.config.record_failures else ''
        return goal

    def evaluate(self, jobs: Sequence[EpisodeJob], on_result) -> None:
        from action_msgs.msg import GoalStatus

        pending = deque(jobs)
        attempts: dict[tuple[int, int], int] = {}
        running: dict[str, Running] = {}
        timeout = self.config.resolved_episode_timeout()
        last_discovery = 0.0
        while pending or running:
            now = time.monotonic()
            if now - last_discovery > 2.0:
                self.discover_workers()
                last_discovery = now
            for name, client in self.clients.items():
                if not pending or name in running or self.quarantine.get(name, 0) > now:
                    continue
                if not client.server_is_ready():
                    continue
                job = pending.popleft()
                running[name] = Running(job, now, client.send_goal_async(self.goal_for(job)))
            if not running and pending and not any(
                    c.server_is_ready() for c in self.clients.values()):
                raise CampaignError('no simulator worker is available any more')
            self.spin(0.01)
            for name, state in list(running.items()):
                retry_reason = None
                if state.goal_handle is None and state.send_future.done():
                    handle = state.send_future.result()
                    if handle is None or not handle.accepted:
                        retry_reason = 'refused the goal'
                    else:
                        state.goal_handle = handle
                        state.result_future = handle.get_result_async()
                if state.result_future is not None and state.result_future.done():
                    response = state.result_future.result()
                    if response.status == GoalStatus.STATUS_SUCCEEDED:
                        del running[name]
                        on_result(state.job, metrics_dict(response.result.metrics))
                        continue
                    retry_reason = f'ended the goal with status {response.status}'
                if retry_reason is None and time.monotonic() - state.started > timeout:
                    retry_reason = f'gave no result within {timeout:.0f} s'
                    if state.goal_handle is not None:
                        state.goal_handle.cancel_goal_async()
                    self.quarantine[name] = time.monotonic() + 60.0
                if retry_reason is not None:
                    del running[name]
                    key = state.job.key
                    attempts[key] = attempts.get(key, 0) + 1
                    if attempts[key] >= self.max_attempts:
                        raise CampaignError(
                            f'episode {state.job.environment.id} failed {attempts[key]} times; '
                            f'last: worker {name} {retry_reason}')
                    self.log(f'worker {name} {retry_reason}: retrying '
                             f'{state.job.environment.id} on another worker')
                    pending.appendleft(state.job)


def metrics_dict(msg) -> dict:
    return {
        'outcome': msg.outcome, 'detail': msg.detail, 'collisions': int(msg.collisions),
        'fault_collisions': int(msg.fault_collisions),
        'static_collisions': int(msg.static_collisions),
        'robot_into_agent_collisions': int(msg.robot_into_agent_collisions),
        'agent_into_robot_collisions': int(msg.agent_into_robot_collisions),
        'proximity_time': float(msg.proximity_time),
        'simulation_time': float(msg.simulation_time), 'risk_score': float(msg.risk_score),
        'fault_risk_score': float(msg.fault_risk_score),
        'invalid_commands': int(msg.invalid_commands),
        'feasible': bool(msg.feasible), 'min_clearance': float(msg.min_clearance),
        'distance_travelled': float(msg.distance_travelled),
        'final_distance_to_goal': float(msg.final_distance_to_goal), 'ticks': int(msg.ticks),
        'wall_time': float(msg.wall_time), 'bag_path': msg.bag_path,
    }


# ---- processes ---------------------------------------------------------------------------


def start_graph(supervisor: ProcessSupervisor, config: CampaignConfig, controller: str,
                external: bool, mode: str, generator_running: bool) -> None:
    if not generator_running:
        # No checkpoint parameter: the campaign sends every member's weights itself.
        supervisor.start('generator', [
            'ros2', 'run', 'sessgan_gen', 'generator', '--ros-args',
            '-r', f'__ns:={GENERATOR_NAMESPACE}', '-p', f'scenario:={config.scenario}',
            '-p', 'rate:=0.0'])
    if external:
        return
    for worker, core in enumerate(worker_cores(config.workers)):
        namespace = f'/w{worker}'
        ros_args = ['--ros-args', '-r', f'__ns:={namespace}']
        supervisor.start(f'simulator_w{worker}', [
            'ros2', 'run', 'sessgan_sim', 'simulator', *ros_args, '-p', f'mode:={mode}',
            '-p', f'bag_storage:={config.bag_storage}'], core=core, batch=True)
        supervisor.start(f'{controller}_w{worker}', [
            'ros2', 'run', 'sessgan_controllers', controller, *ros_args,
            '-p', 'use_sim_time:=true'], core=core, batch=True)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        config = config_from_args(args)
        config.validate()
    except (SessganEvolverError, SessganGenError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    run_name = args.run or f'{config.scenario}-seed{config.seed}'
    controller = config.controller or get_scenario(config.scenario).controller
    if args.external:
        controller = config.controller or 'external'

    def log(message: str) -> None:
        print(f'[campaign] {message}', file=sys.stderr, flush=True)

    try:
        campaign = Campaign(config, run_name, args.runs_root, args.bags_root, log)
    except (SessganEvolverError, SessganGenError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2

    # SIGTERM ends the campaign like Ctrl-C, so the children are stopped too.
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    if args.in_process:
        return run_in_process(campaign, config, controller, run_name, args.resume, log)

    import rclpy
    rclpy.init(args=['--ros-args'])
    node = rclpy.create_node('sessgan_evolver')
    supervisor = ProcessSupervisor(campaign.store.run_dir / 'logs')
    try:
        evaluator = RosEvaluator(node, config, campaign.bags_dir, controller, supervisor, log)
        generator_running = evaluator.generator.wait_for_service(timeout_sec=1.0)
        if not args.external:
            evaluator.allowed = {f'/w{i}/evaluate' for i in range(config.workers)}
            evaluator.wait_until_absent(sorted(evaluator.allowed), timeout=15.0)
        start_graph(supervisor, config, controller, args.external, args.mode, generator_running)
        log(f'run {run_name}: {config.generations} generations x {config.population} members x '
            f'{config.maps_per_member} maps, scenario {config.scenario}, controller '
            f'{controller}, ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}')
        evaluator.wait_for_generator(timeout=120.0)
        evaluator.wait_for_workers(1 if args.external else config.workers, timeout=120.0)
        result = campaign.run(evaluator, resume=args.resume)
    except KeyboardInterrupt:
        log('interrupted: stopping every process this campaign started '
            f'(continue later with --resume --run {run_name})')
        return 130
    except (SessganEvolverError, SessganGenError) as err:
        log(f'error: {err}')
        return 1
    finally:
        supervisor.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()
    report_result(result, log)
    return 0


def run_in_process(campaign: Campaign, config: CampaignConfig, controller: str, run_name: str,
                   resume: bool, log: Callable[[str], None]) -> int:
    """The campaign with sessgan_evolver.in_process's evaluator: no ROS at all."""
    from sessgan_evolver.in_process import InProcessEvaluator

    log(f'run {run_name}: {config.generations} generations x {config.population} members x '
        f'{config.maps_per_member} maps, scenario {config.scenario}, controller {controller}, '
        'in process')
    try:
        with InProcessEvaluator(
                config.scenario, controller, config.time_limit,
                record_directory=campaign.bags_dir if config.record_failures else None,
                bag_storage=config.bag_storage) as evaluator:
            result = campaign.run(evaluator, resume=resume)
    except KeyboardInterrupt:
        log(f'interrupted (continue later with --resume --run {run_name} --in-process)')
        return 130
    except (SessganEvolverError, SessganGenError) as err:
        log(f'error: {err}')
        return 1
    report_result(result, log)
    return 0


def report_result(result, log: Callable[[str], None]) -> None:
    first, last = result.generations[0], result.generations[-1]
    log(f'done in {result.wall_time / 60:.1f} min: mean risk '
        f'{first["mean_risk_score"] or 0:.3f} (generation 0) -> '
        f'{last["mean_risk_score"] or 0:.3f} (generation {last["generation"]})')
    print(f'report: {result.report_path}')
    print(f'failure bags: {result.bags_dir}')


if __name__ == '__main__':
    sys.exit(main())
