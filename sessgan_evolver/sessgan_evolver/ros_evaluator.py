"""The campaign's evaluator on the ROS graph: the generator's ``generate_environments``
service for maps, every discovered ``evaluate`` action server for episodes, in parallel.

Used by ``campaign`` (``campaign_cli``), ``suite`` and the workers' episode runner; it imports
no ROS at module level, so the commands' ``--help`` works without ROS.
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sessgan_core.environment import Environment
from sessgan_core.ros_spin import spin_interruptibly
from sessgan_evolver.campaign import CampaignConfig, CampaignError, EpisodeJob
from sessgan_evolver.errors import BagCollectionError, HarnessFailureError
from sessgan_evolver.harness import HarnessRetries
from sessgan_evolver.process_supervisor import (
    ChildProcess,
    ProcessSupervisor,
    WorkerPair,
    WorkerPool,
)
from sessgan_sim.metrics import Outcome, is_harness_outcome

if TYPE_CHECKING:  # ROS types, imported where they are used so --help works without ROS
    from rclpy.action import ActionClient
    from rclpy.node import Node

    from sessgan_interfaces.action import EvaluateEnvironment

EVALUATE_TYPE = 'sessgan_interfaces/action/EvaluateEnvironment'
GENERATOR_NAMESPACE = '/sessgan'
SIMULATOR_READY_LOG = 'simulator ready'
"""What a simulator logs once its action server is up (a restarted pair waits for it)."""
GENERATOR_TIMEOUT = 120.0
"""Wall seconds the generator may take to answer one request."""
GOAL_ANSWER_TIMEOUT = 15.0
"""Wall seconds a worker may take to accept or refuse a goal before it is sent again."""
NO_WORKER_TIMEOUT = 60.0
"""Wall seconds without any usable worker before the campaign gives up."""
RESTART_READY_TIMEOUT = 120.0
"""Wall seconds a restarted simulator may take to say it is ready."""
IDENTITY_TIMEOUT = 30.0
"""Wall seconds a newly discovered worker may take to say what it is."""
GONE_GRACE = 2.0
"""Wall seconds a worker running an episode may be missing from the graph before the episode
is taken back (DDS drops a host that vanished once its lease expires: 20 s in Fast DDS)."""
CANCEL_DELIVERY = 0.2
"""Wall seconds a stopped campaign waits for its cancel requests to reach the workers."""


def served_actions(node: Node, action_type: str) -> list[str]:
    """Names of the actions of ``action_type`` that some node serves. The graph names an
    action as soon as a client of it exists (the client makes the same topics and services),
    and a client left over in another process is no simulator; only servers publish the
    action's status topic."""
    from rclpy.action import get_action_names_and_types

    return [name for name, types in get_action_names_and_types(node)
            if action_type in types and node.count_publishers(f'{name}/_action/status') > 0]


@dataclass
class CampaignOverhead:
    """Wall seconds the campaign itself spent around its episodes (what limits how many
    workers one campaign keeps busy; tests/benchmarks/bench_multihost.py)."""

    episodes: int = 0
    """Results told (harness re-runs excluded)."""
    generator: float = 0.0
    """Waiting for the generator's maps."""
    dispatch: float = 0.0
    """Per episode: goal sent to result received, less the worker's own episode wall time
    (goal and result messaging, world build, the dispatch loop's polling)."""
    bags: int = 0
    """Failure bags copied from the workers."""
    bags_in_place: int = 0
    """Failure bags a worker wrote into the campaign's own bags folder (nothing to copy)."""
    bag_transfer: float = 0.0
    """Copying failure bags from the workers (sessgan_evolver.bag_collection)."""
    cpu: float = 0.0
    """CPU seconds of the campaign process over the run (its search, checkpoints and report
    included; the generator is a process of its own)."""

    def summary(self) -> str:
        per = 1e3 / max(1, self.episodes)
        return (f'campaign overhead per episode ({self.episodes} episodes): generator '
                f'{self.generator * per:.1f} ms, dispatch {self.dispatch * per:.1f} ms, bag '
                f'transfer {self.bag_transfer * per:.1f} ms ({self.bags} bags copied, '
                f'{self.bag_transfer * 1e3 / max(1, self.bags):.1f} ms each; '
                f'{self.bags_in_place} written in place by the workers); campaign '
                f'process CPU {self.cpu * per:.1f} ms')


@dataclass
class RunningEpisode:
    job: EpisodeJob
    started: float
    send_future: Any
    goal_handle: Any = None
    result_future: Any = None
    gone_since: float | None = None
    """When its worker's action server was first seen missing from the graph."""


class RosEvaluator:
    """Generator service + every discovered ``evaluate`` action server, dispatched in parallel.

    A worker that refuses a goal, aborts it or stalls past the episode timeout gets the job
    taken away and retried on another worker; a worker that stalled is quarantined for a
    minute. The simulator + controller pairs this campaign started (``pool``) are polled every
    loop: when a process of a pair dies, the episode it was running is a harness failure, not
    a result (it never reaches the fitness or the metrics); the pair is restarted and the
    episode run again. A pair that keeps dying is quarantined for good.
    """

    def __init__(self, node: Node, config: CampaignConfig, record_directory: Path,
                 controller: str, supervisor: ProcessSupervisor,
                 log: Callable[[str], None], pool: WorkerPool | None = None) -> None:
        from rclpy.action import ActionClient

        from sessgan_interfaces.srv import GenerateEnvironments

        self.node = node
        self.supervisor = supervisor
        self.pool = pool if pool is not None else WorkerPool(supervisor)
        self.generator_process: ChildProcess | None = None
        self.config = config
        self.record_directory = record_directory  # relative to the simulators' bags root
        self.controller = controller
        self.log = log
        self.action_client_class = ActionClient
        self.generator = node.create_client(GenerateEnvironments,
                                            f'{GENERATOR_NAMESPACE}/generate_environments')
        self.clients: dict[str, ActionClient] = {}
        self.allowed: set[str] | None = None  # None: every discovered worker (--external)
        self.quarantine: dict[str, float] = {}
        self.starting: dict[str, float] = {}
        """Action names of restarted pairs whose new simulator is not ready yet, with the
        monotonic time by which it must be."""
        self.max_attempts = 3
        """Requests of one member the generator may die on."""
        self.retries = HarnessRetries(config.harness_tries, log, config.adaptive_rtf)
        self.overhead = CampaignOverhead()
        self.collect_into: Path | None = None
        """Where failure bags of workers are copied (the campaign's bags/<run>), or None."""
        self.remove_collected = False
        """Remove a worker's copy of a bag once it is collected."""
        self.bag_sources: dict[str, Any] = {}
        self.expected_robot: str | None = None
        """The robot a worker's simulator must host (its version must be ours), or None:
        workers are not checked (sessgan_evolver.worker_identity)."""
        self.refused: set[str] = set()
        self.said_shared: set[str] = set()
        """Workers served by several simulators at the last look (said once)."""
        self.unidentified: dict[str, float] = {}
        """Workers whose bags service was not up yet, with when that was first seen."""

    rerun_harness_outcomes = True
    """Run a harness outcome again here (never told); False: tell it, for a caller that
    judges harness outcomes itself (``suite``)."""

    @property
    def harness_reruns(self) -> int:
        return self.retries.reruns

    def spin(self, seconds: float = 0.02) -> None:
        import rclpy
        spin_interruptibly(lambda: rclpy.spin_once(self.node, timeout_sec=seconds))

    def check_children(self) -> None:
        """Fail fast when a process this campaign started has died (while starting up)."""
        for child in self.supervisor.dead_children():
            raise CampaignError(f'{child.name} {child.exit_description()}:'
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
        return served_actions(self.node, EVALUATE_TYPE)

    def wait_until_absent(self, names: list[str], timeout: float) -> None:
        """Wait for workers of an earlier (killed) campaign to go away before starting ours."""
        deadline = time.monotonic() + timeout
        present: list[str] = []
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
            if name not in self.clients and name not in self.starting:
                if name in self.refused or self.shared(name) \
                        or not self.identity_checked(name):
                    continue
                from sessgan_interfaces.action import EvaluateEnvironment
                self.clients[name] = self.action_client_class(
                    self.node, EvaluateEnvironment, name)
                self.log(f'worker found: {name}')
        return sorted(self.clients)

    def shared(self, name: str) -> bool:
        """Whether more than one simulator serves ``name`` (two started under one namespace):
        each goal would go to both, and their answers would cross. Said once; looked at
        again at each discovery, so the worker is used once the others are stopped."""
        servers = self.node.count_publishers(f'{name}/_action/status')
        if servers > 1 and name not in self.said_shared:
            self.log(f'not using worker {name} while {servers} simulators serve it (started '
                     'twice under one namespace?): stop all but one')
        (self.said_shared.add if servers > 1 else self.said_shared.discard)(name)
        return servers > 1

    def identity_checked(self, name: str) -> bool:
        """True if worker ``name`` may be used (or is not checked). One of another version or
        robot is refused for good, with the difference logged; one whose ``bags`` service is
        not up yet is looked at again at the next discovery (never waited for here, so it
        cannot stall the dispatch loop), and refused once it has been missing for
        ``IDENTITY_TIMEOUT``."""
        if self.expected_robot is None:
            return True
        from sessgan_evolver import __version__
        from sessgan_evolver.remote_bags import RemoteBagSource
        from sessgan_evolver.worker_identity import worker_difference

        namespace = name.rsplit('/', 1)[0]
        if namespace not in self.bag_sources:  # one client a worker: not one a discovery
            self.bag_sources[namespace] = RemoteBagSource(self.node, namespace, self.spin)
        source = self.bag_sources[namespace]
        why = None
        if not source.client.service_is_ready():
            first_seen = self.unidentified.setdefault(name, time.monotonic())
            if time.monotonic() - first_seen < IDENTITY_TIMEOUT:
                return False
            why = (f'worker {name}: it serves no {source.service} service within '
                   f'{IDENTITY_TIMEOUT:.0f} s, so it cannot say its version or send its '
                   'failure bags (a sessgan version without it?)')
        else:
            try:
                description = source.call_within(IDENTITY_TIMEOUT)
            except BagCollectionError as err:
                self.log(f'worker {name}: not used yet: {err}')
                return False
            why = worker_difference(name, description.software_version,
                                    description.settings, __version__, self.expected_robot,
                                    self.config.scenario)
        self.unidentified.pop(name, None)
        if why:
            self.refused.add(name)
            self.log(f'refusing {why}')
            return False
        return True

    def wait_for_workers(self, count: int, timeout: float) -> None:
        """Wait until ``count`` evaluate servers answer; CampaignError after ``timeout`` wall
        seconds. Says what it waits for once a few seconds went by without them (a user's
        stack not started yet looks like a hang otherwise)."""
        deadline = time.monotonic() + timeout
        announce: float | None = time.monotonic() + 3.0
        ready: list[str] = []
        while time.monotonic() < deadline:
            ready = [n for n in self.discover_workers() if self.clients[n].server_is_ready()]
            if len(ready) >= count:
                return
            if announce is not None and time.monotonic() >= announce:
                self.log(f'waiting up to {timeout:.0f} s for {count} simulator worker(s) '
                         f'(evaluate action servers) in ROS_DOMAIN_ID='
                         f'{os.environ.get("ROS_DOMAIN_ID", "0")}; {len(ready)} answer so far')
                announce = None
            self.check_children()
            self.spin(0.1)
        raise CampaignError(self.missing_workers(count, ready, timeout))

    def missing_workers(self, count: int, ready: Sequence[str], timeout: float) -> str:
        """Why too few workers answered: what was looked for and found and, for workers this
        process did not start (a user's stack, --external), what to check."""
        wanted = (', '.join(sorted(self.allowed)) if self.allowed is not None
                  else 'any <namespace>/evaluate, e.g. /w0/evaluate')
        servers = self.evaluate_servers()
        unused = sorted(name for name in servers if name not in ready
                        and (self.allowed is None or name in self.allowed))
        others = sorted(name for name in servers
                        if self.allowed is not None and name not in self.allowed)
        text = (f'only {len(ready)} of {count} simulator workers answered within '
                f'{timeout:.0f} s (looked for {EVALUATE_TYPE} action servers: {wanted}; '
                + (f'found but not ready or refused: {", ".join(unused)}' if unused
                   else 'found none')
                + (f'; not asked for, but running: {", ".join(others)}' if others else '')
                + ')')
        if self.pool.pairs:  # workers we started: their logs say why
            return text
        return (f'{text}. Start a simulator beside your controller, e.g. `ros2 run sessgan_sim '
                'simulator --ros-args -r __ns:=/w0`, with the same ROS_DOMAIN_ID (here '
                f'{os.environ.get("ROS_DOMAIN_ID") or "unset: 0"}) and '
                'ROS_AUTOMATIC_DISCOVERY_RANGE (here '
                f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "unset: SUBNET"}) as this '
                'command')

    def no_worker_hint(self) -> str:
        """What to do when every worker is gone mid-run."""
        if self.pool.pairs:  # workers we started: restarted by the supervisor, logs say why
            return f'the logs of the workers this command started: {self.supervisor.log_directory}'
        return ('start a simulator again beside your controller (e.g. `ros2 run sessgan_sim '
                'simulator --ros-args -r __ns:=/w0`, in this ROS_DOMAIN_ID) and check the log of '
                'the one that left')

    def sample(self, weights: bytes, seeds: Sequence[int], generation: int,
               member: int) -> list[Environment]:
        from sessgan_core.ros_conversion import environment_from_msg
        from sessgan_interfaces.srv import GenerateEnvironments

        request = GenerateEnvironments.Request(
            scenario=self.config.scenario, seeds=[int(s) for s in seeds],
            generation=generation, member=member, height=self.config.height,
            width=self.config.width)
        request.weights = weights
        asked = time.monotonic()
        for attempt in range(1, self.max_attempts + 1):
            future = self.generator.call_async(request)
            deadline = time.monotonic() + GENERATOR_TIMEOUT
            while not future.done():
                if self.restart_generator_if_dead(attempt):
                    break
                if time.monotonic() > deadline:
                    raise CampaignError(
                        f'the generator did not answer within {GENERATOR_TIMEOUT:.0f} s')
                self.spin(0.05)
            if future.done():
                break
        response = future.result()
        self.overhead.generator += time.monotonic() - asked
        if not response.success:
            raise CampaignError(f'the generator refused member {member}: {response.message}')
        environments = [environment_from_msg(msg) for msg in response.environments]
        stations = self.config.mission_stations
        for environment in environments:
            if environment.feasible and len(environment.stations) != stations:
                raise CampaignError(
                    f'the generator drew {len(environment.stations)} mission stations on '
                    f'{environment.id}, the campaign asks for {stations}: a generator already '
                    f'running under {GENERATOR_NAMESPACE} has its own mission_stations '
                    'parameter; stop it or start it with the same one')
            if environment.feasible and environment.robots != self.config.robots:
                raise CampaignError(
                    f'the generator drew {environment.robots} robots on {environment.id}, the '
                    f'campaign asks for {self.config.robots}: a generator already running '
                    f'under {GENERATOR_NAMESPACE} has its own robots parameter; stop it or '
                    'start it with the same one')
        return environments

    def restart_generator_if_dead(self, attempt: int) -> bool:
        """True (and the generator restarted) if the generator this campaign started died;
        CampaignError if it died on each of ``max_attempts`` requests."""
        child = self.generator_process
        if child is None or child.alive:
            return False
        report = f'{child.name} {child.exit_description()}'
        if attempt >= self.max_attempts:
            raise CampaignError(f'{report} on {attempt} requests in a row:\n{child.log_tail()}')
        self.log(f'{report}: restarting it and asking again')
        self.generator_process = self.supervisor.restart(child)
        self.wait_for_generator(timeout=120.0)
        return True

    def goal_for(self, job: EpisodeJob) -> EvaluateEnvironment.Goal:
        from sessgan_core.ros_conversion import environment_to_msg
        from sessgan_interfaces.action import EvaluateEnvironment

        goal = EvaluateEnvironment.Goal()
        goal.environment = environment_to_msg(job.environment)
        goal.seed = int(job.seed)
        goal.time_limit = float(self.config.time_limit)
        goal.controller = self.controller
        goal.record_directory = str(self.record_directory) if self.config.record_failures else ''
        goal.real_time_factor_scale = self.real_time_factor_scale(job)
        return goal

    def real_time_factor_scale(self, job: EpisodeJob) -> float:
        """The pace of ``job``'s next try (the goal's real_time_factor_scale; 0: the
        simulator's own): slower after overloaded tries with --adaptive-rtf."""
        return self.retries.real_time_factor_scale(job.key)

    def pair_of(self, name: str) -> WorkerPair | None:
        """The pair this campaign started behind action ``name`` (None for external ones)."""
        return self.pool.pairs.get(name.rsplit('/', 1)[0])

    def drop_client(self, name: str) -> None:
        client = self.clients.pop(name, None)
        if client is not None:
            client.destroy()

    def take_back_from_dead_pairs(self, running: dict[str, RunningEpisode]
                                  ) -> list[EpisodeJob]:
        """Restart every pair with a dead process; returns the jobs they were running, which
        have no result (a harness failure, never an episode outcome)."""
        taken = []
        for pair in self.pool.dead_pairs():
            name = f'{pair.namespace}/evaluate'
            state = running.pop(name, None)
            report = pair.death_report()
            if state is not None:
                taken.append(state.job)
                self.log(f'worker {pair.namespace}: {report} during episode '
                         f'{state.job.environment.id}: a harness failure, not a result; the '
                         'episode will run again')
            else:
                self.log(f'worker {pair.namespace}: {report}')
            self.drop_client(name)
            self.starting.pop(name, None)
            if self.pool.restart(pair):
                self.starting[name] = time.monotonic() + RESTART_READY_TIMEOUT
                self.log(f'worker {pair.namespace}: restarted its simulator and controller '
                         f'(restart {pair.restarts} of {self.pool.max_restarts})')
            else:
                if self.allowed is not None:
                    self.allowed.discard(name)
                self.log(f'worker {pair.namespace}: died {pair.restarts + 1} times; quarantined '
                         f'for the rest of the campaign (logs: {pair.simulator.log_path.parent})')
                if not self.pool.pairs:
                    raise CampaignError(f'every simulator worker died repeatedly; last: '
                                        f'{report}:\n{pair.simulator.log_tail(1000)}\n'
                                        + '\n'.join(child.log_tail(1000)
                                                    for child in pair.controllers))
        for name, deadline in list(self.starting.items()):
            restarted = self.pair_of(name)
            if restarted is None:
                self.starting.pop(name)
            elif restarted.logged_since_start(SIMULATOR_READY_LOG):
                self.starting.pop(name)  # discover_workers makes a new client for it
            elif time.monotonic() > deadline:
                # Stopped, its pair counts as dead in the next loop: restarted or quarantined.
                self.log(f'worker {restarted.namespace}: its restarted simulator did not log '
                         f'{SIMULATOR_READY_LOG!r} within {RESTART_READY_TIMEOUT:.0f} s')
                self.supervisor.stop([restarted.simulator], grace_seconds=0.0)
        return taken

    def evaluate(self, jobs: Sequence[EpisodeJob],
                 on_result: Callable[[EpisodeJob, dict], None]) -> None:
        running: dict[str, RunningEpisode] = {}
        try:
            self.dispatch(jobs, on_result, running)
        except KeyboardInterrupt:
            # Stopped (Ctrl-C): a user's simulators would run these episodes on to their end
            # and write their failure bags into the run; cancelled, they end at once as
            # cancelled, which writes none. The pause lets DDS deliver the requests.
            handles = [state.goal_handle for state in running.values()
                       if state.goal_handle is not None]
            for handle in handles:
                handle.cancel_goal_async()
            if handles:
                time.sleep(CANCEL_DELIVERY)
            raise

    def dispatch(self, jobs: Sequence[EpisodeJob], on_result: Callable[[EpisodeJob, dict], None],
                 running: dict[str, RunningEpisode]) -> None:
        """:meth:`evaluate`'s loop; ``running``: the episodes on the workers, by worker."""
        from action_msgs.msg import GoalStatus

        pending = deque(jobs)
        last_discovery = 0.0
        last_worker_seen = time.monotonic()
        announced_wait = False
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
                running[name] = RunningEpisode(job, now,
                                               client.send_goal_async(self.goal_for(job)))
            if running or self.starting or any(
                    c.server_is_ready() for c in self.clients.values()):
                last_worker_seen = now
                announced_wait = False
            elif now - last_worker_seen > NO_WORKER_TIMEOUT:
                raise HarnessFailureError(
                    f'no simulator worker has been available for {NO_WORKER_TIMEOUT:.0f} s '
                    f'({len(pending)} episodes left to run); {self.no_worker_hint()}')
            elif not announced_wait and now - last_worker_seen > 3.0:
                self.log(f'no simulator worker answers: waiting up to '
                         f'{NO_WORKER_TIMEOUT:.0f} s for one; {self.no_worker_hint()}')
                announced_wait = True
            self.spin(0.01)
            for job in self.take_back_from_dead_pairs(running):
                self.retries.failed(job.key, job.environment.id, 'a worker process died',
                                    f'logs in {self.supervisor.log_directory}')
                pending.appendleft(job)
            for name, state in list(running.items()):
                retry_reason = None
                if state.goal_handle is None and state.send_future.done():
                    handle = state.send_future.result()
                    if handle is None or not handle.accepted:
                        retry_reason = 'refused the goal'
                    else:
                        state.goal_handle = handle
                        state.result_future = handle.get_result_async()
                elif (state.goal_handle is None
                      and time.monotonic() - state.started > GOAL_ANSWER_TIMEOUT):
                    # A goal sent while discovery still showed a just-restarted worker's
                    # predecessor is lost; send it again, through a new client (new DDS
                    # endpoints, matched afresh) made at the next discovery.
                    retry_reason = f'did not answer the goal within {GOAL_ANSWER_TIMEOUT:.0f} s'
                    self.drop_client(name)
                if state.result_future is not None and state.result_future.done():
                    response = state.result_future.result()
                    if response.status == GoalStatus.STATUS_SUCCEEDED:
                        metrics = metrics_dict(response.result.metrics)
                        pair = self.pair_of(name)
                        if (metrics['outcome'] == Outcome.CONTROLLER_UNRESPONSIVE
                                and pair is not None
                                and not all(child.alive for child in pair.controllers)):
                            continue  # its controller died: the next loop re-runs it
                        del running[name]
                        if self.rerun_harness_outcomes and is_harness_outcome(metrics['outcome']):
                            # No result: never recorded (sessgan_evolver.harness).
                            self.retries.failed(state.job.key, state.job.environment.id,
                                                metrics['outcome'],
                                                f'worker {name}: {metrics["detail"]}')
                            pending.appendleft(state.job)
                            continue
                        try:
                            self.collect_bag(name, state.job, metrics)
                        except BagCollectionError as err:
                            # The result has no bag here: a harness failure, run again.
                            self.retries.failed(state.job.key, state.job.environment.id,
                                                'failure bag not collected',
                                                f'worker {name}: {err}')
                            pending.appendleft(state.job)
                            continue
                        self.retries.succeeded(state.job.key)
                        self.overhead.episodes += 1
                        self.overhead.dispatch += max(0.0, time.monotonic() - state.started
                                                      - float(metrics['wall_time']))
                        on_result(state.job, metrics)
                        continue
                    retry_reason = f'ended the goal with status {response.status}'
                if retry_reason is None and state.goal_handle is not None:
                    retry_reason = self.gone(name, state)
                timeout = self.config.episode_timeout_for(state.job.environment.occupancy.size)
                # A slower re-run (--adaptive-rtf) takes longer in wall time.
                timeout /= self.real_time_factor_scale(state.job) or 1.0
                if retry_reason is None and time.monotonic() - state.started > timeout:
                    retry_reason = f'gave no result within {timeout:.0f} s'
                    if state.goal_handle is not None:
                        state.goal_handle.cancel_goal_async()
                    self.quarantine[name] = time.monotonic() + 60.0
                if retry_reason is not None:
                    del running[name]
                    self.retries.failed(state.job.key, state.job.environment.id,
                                        f'worker {name}', retry_reason)
                    pending.appendleft(state.job)

    def gone(self, name: str, state: RunningEpisode) -> str | None:
        """Why the episode of ``state`` is to be taken back from worker ``name``: its action
        server left the graph (its host or processes are gone) for ``GONE_GRACE``; else None.
        A worker that comes back is given work again (its client is kept)."""
        if self.clients[name].server_is_ready():
            state.gone_since = None
            return None
        now = time.monotonic()
        if state.gone_since is None:
            state.gone_since = now
        if now - state.gone_since < GONE_GRACE:
            return None
        return 'left the ROS graph during the episode (its host or processes are gone)'

    def bag_places(self, job: EpisodeJob) -> tuple[str, Path]:
        """Where the failure bag of ``job`` is: its folder under a worker's bags root (the
        goal's record directory), and the folder here it is collected into."""
        assert self.collect_into is not None
        return str(self.record_directory), self.collect_into

    def collect_bag(self, name: str, job: EpisodeJob, metrics: dict) -> None:
        """Copy the failure bag of a result into ``collect_into`` (verified:
        sessgan_evolver.bag_collection) and point ``metrics['bag_path']`` at the copy."""
        if not metrics.get('bag_path'):
            return
        if self.collect_into is None:  # workers this campaign started write into its bags
            self.overhead.bags_in_place += 1
            return
        remote, local = self.bag_places(job)
        final = local / job.environment.id
        if Path(metrics['bag_path']).resolve() == final.resolve():
            self.overhead.bags_in_place += 1  # the worker writes into this campaign's root
            return
        from sessgan_evolver.bag_collection import collect_bag
        from sessgan_evolver.remote_bags import RemoteBagSource

        namespace = name.rsplit('/', 1)[0]
        if namespace not in self.bag_sources:
            self.bag_sources[namespace] = RemoteBagSource(self.node, namespace, self.spin)
        started = time.monotonic()
        metrics['bag_path'] = str(collect_bag(
            self.bag_sources[namespace], f'{remote}/{job.environment.id}', local,
            remove=self.remove_collected))
        seconds = time.monotonic() - started
        self.overhead.bag_transfer += seconds
        self.overhead.bags += 1
        self.log(f'failure bag of {job.environment.id} collected from {namespace} '
                 f'in {seconds:.2f} s')


def metrics_dict(msg) -> dict:
    return {
        'outcome': msg.outcome, 'detail': msg.detail, 'collisions': int(msg.collisions),
        'fault_collisions': int(msg.fault_collisions),
        'static_collisions': int(msg.static_collisions),
        'robot_into_agent_collisions': int(msg.robot_into_agent_collisions),
        'agent_into_robot_collisions': int(msg.agent_into_robot_collisions),
        'robot_into_robot_collisions': int(msg.robot_into_robot_collisions),
        'robot_hit_by_robot_collisions': int(msg.robot_hit_by_robot_collisions),
        'proximity_time': float(msg.proximity_time),
        'simulation_time': float(msg.simulation_time), 'risk_score': float(msg.risk_score),
        'fault_risk_score': float(msg.fault_risk_score),
        'invalid_commands': int(msg.invalid_commands),
        'feasible': bool(msg.feasible), 'min_clearance': float(msg.min_clearance),
        'distance_travelled': float(msg.distance_travelled),
        'final_distance_to_goal': float(msg.final_distance_to_goal), 'ticks': int(msg.ticks),
        'wall_time': float(msg.wall_time), 'bag_path': msg.bag_path,
        'bag_error': msg.bag_error,
        'legs': int(msg.legs), 'legs_completed': int(msg.legs_completed),
        'leg_times': [float(value) for value in msg.leg_times],
        'failed_leg': int(msg.failed_leg),
        'success': bool(msg.success),
        # NaN (not reached, no route) becomes None, as EpisodeMetrics.to_dict writes it.
        **{name: finite_or_none(getattr(msg, name)) for name in (
            'time_to_goal', 'path_length_ratio', 'mean_clearance', 'linear_jerk',
            'angular_jerk', 'mean_speed')},
    }


def finite_or_none(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None
