"""Benchmark: the simulator node in lockstep with a controller in a separate process.

The factory reference episode (example map, 360-beam scan, 20 Hz control, the Nearness-Diagram
controller in its own process with use_sim_time, so clock, odom and scan reach it every tick).
Prints:
* the floor: bare rclpy processes exchanging the same messages per tick with no simulation and
  no controller logic (lockstep_floor.py), on one core, measured first in the same run, in wall
  time and in CPU time;
* the simulator and its controller on one core as batch processes (how campaigns start them):
  the sim-time / wall-time factor and its share of the floor's, the time per tick split into
  physics, sensors, metrics (the node's own timing), the controller's computation (the same
  episodes run in-process, as the node runs them) and messaging (the rest: ROS 2 publishing,
  delivery and callbacks on both sides, against the floor), and the CPU time per tick of each
  process against the floor's (on a machine busy with other work, the figure that moves
  least);
* the same pair with default scheduling, and on two cores (one process per core);
* throughput of 2 workers against 1, each worker's pair on its own core, in episodes per minute,
  next to the same ratio for a pure-Python busy loop (the machine's own scaling).

Every wait has a timeout (``--timeout``) and every measurement its own namespace; a wait that
runs out or a process that dies ends the benchmark with what it waited for.

Run after `source setup.bash`:  python tests/benchmarks/bench_simulator_node.py [--episodes N]
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import random
import re
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from sessgan_core.ros_spin import init_rclpy, run_command
from sessgan_evolver.process_supervisor import ChildProcess, ProcessSupervisor, worker_cores

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randrange(10, 100)))

HERE = Path(__file__).resolve().parent
TIMING = re.compile(r'\(x([\d.]+) real time\); per tick ms: physics=([\d.]+) sensors=([\d.]+) '
                    r'metrics=([\d.]+) messaging=([\d.]+)')
REFERENCE_PARAMETERS = ['-p', 'lidar_beams:=360', '-p', 'control_rate:=20.0']
EPISODE_TIMEOUT = 120.0
"""Wall seconds any one wait may take (a server to come up, an episode to be accepted or
answered; a reference episode takes about half a second): a loaded machine slows it, a lost
goal never ends."""
FLOOR_TIMEOUT = 300.0
"""Wall seconds the floor's ticks may take."""


class Floor(NamedTuple):
    ticks_per_second: float
    cpu_ms: float
    """CPU ms a tick of both floor processes together."""


def measure_floor(graph: ProcessSupervisor, core: int, ticks: int) -> Floor:
    """Lockstep ticks per second of bare rclpy with the reference messages, on ``core``, as
    batch processes (like the campaign's workers), and their CPU time a tick."""
    script = str(HERE / 'lockstep_floor.py')
    number = next(_worker_numbers)
    ns = ['--ros-args', '-r', f'__ns:=/floor{number}']
    controller = graph.start(f'floor_controller{number}', [sys.executable, script, '--role',
                                                           'controller', *ns],
                             core=core, batch=True)
    sim = graph.start(f'floor_sim{number}', [sys.executable, script, '--role', 'sim', '--ticks',
                                             str(ticks), *ns], core=core, batch=True)
    deadline = time.monotonic() + FLOOR_TIMEOUT
    controller_cpu = []  # at the start and at the end of the measured ticks
    for awaited in ('measuring', 'ticks_per_second'):
        while awaited not in sim.output():
            if not sim.alive and awaited not in sim.output():
                sys.exit(f'the lockstep floor {sim.exit_description()}:\n{sim.log_tail()}')
            if time.monotonic() > deadline:
                sys.exit(f'the lockstep floor did not finish {ticks} ticks within '
                         f'{FLOOR_TIMEOUT:.0f} s:\n{sim.log_tail()}')
            time.sleep(0.01)
        controller_cpu.append(group_cpu_seconds(controller.process.pid))
    found = re.search(r'ticks_per_second=([\d.]+) cpu_ms_per_tick=([\d.]+)', sim.output())
    graph.stop_all()
    if not found:
        sys.exit(f'the lockstep floor failed:\n{sim.log_tail()}')
    controller_ms = (controller_cpu[1] - controller_cpu[0]) / ticks * 1e3
    return Floor(float(found.group(1)), float(found.group(2)) + controller_ms)


def group_cpu_seconds(group: int) -> float:
    """CPU seconds (user + system) the live processes of process group ``group`` used so far
    (a child started by ProcessSupervisor leads its group; ``ros2 run`` runs the node as its
    child)."""
    ticks_per_second = os.sysconf('SC_CLK_TCK')
    total = 0
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if int(fields[2]) == group:
            total += int(fields[11]) + int(fields[12])
    return total / ticks_per_second


_worker_numbers = itertools.count()


@dataclass
class Worker:
    """A simulator worker and its ND controller, in a namespace of their own."""

    namespace: str
    simulator: ChildProcess
    controller: ChildProcess

    def death(self) -> str | None:
        """Why one of the pair is no longer running, with its log; None while both run."""
        for child in (self.simulator, self.controller):
            if not child.alive:
                return (f'the {child.name} process of {self.namespace} '
                        f'{child.exit_description()}:\n{child.log_tail()}')
        return None


def start_worker(graph: ProcessSupervisor, sim_core: int, controller_core: int,
                 batch: bool = True) -> Worker:
    """A simulator worker and its ND controller in a fresh namespace /bench<n>: a client never
    meets a server of an earlier measurement that discovery still lists after it stopped (a
    goal sent to that one is never answered)."""
    number = next(_worker_numbers)
    namespace = f'/bench{number}'
    args = ['--ros-args', '-r', f'__ns:={namespace}']
    simulator = graph.start(f'sim{number}', ['ros2', 'run', 'sessgan_sim', 'simulator', *args,
                                             *REFERENCE_PARAMETERS], core=sim_core, batch=batch)
    controller = graph.start(f'ctl{number}', ['ros2', 'run', 'sessgan_controllers',
                                              'nearness_diagram', *args, '-p',
                                              'use_sim_time:=true'],
                             core=controller_core, batch=batch)
    return Worker(namespace, simulator, controller)


def run_episodes(node, workers: list[Worker], environment_msg, episodes: int,
                 results: list | None = None, expect: str | None = 'goal_reached',
                 timeout: float = EPISODE_TIMEOUT) -> float:
    """Run ``episodes`` reference episodes (seeds ``episodes`` down to 1) spread over the
    workers; return wall seconds. Each episode's metrics go to ``results``; an outcome other
    than ``expect`` ends the benchmark, and so does a wait longer than ``timeout`` wall
    seconds (for a server, a goal's acceptance or its result) or a worker process that died:
    the message names what was awaited."""
    import rclpy
    from rclpy.action import ActionClient

    from sessgan_interfaces.action import EvaluateEnvironment

    clients = [ActionClient(node, EvaluateEnvironment, f'{worker.namespace}/evaluate')
               for worker in workers]
    try:
        for worker, client in zip(workers, clients):
            deadline = time.monotonic() + timeout
            while not client.wait_for_server(timeout_sec=0.5):
                check_worker(worker)
                if time.monotonic() > deadline:
                    sys.exit(f'the evaluate server {worker.namespace}/evaluate did not come up '
                             f'within {timeout:.0f} s')
        remaining = episodes
        running: dict[int, Pending] = {}
        start = time.monotonic()
        while remaining or running:
            for index, client in enumerate(clients):
                if index not in running and remaining:
                    goal = EvaluateEnvironment.Goal(environment=environment_msg, seed=remaining)
                    running[index] = Pending(remaining, client.send_goal_async(goal),
                                             time.monotonic() + timeout)
                    remaining -= 1
            rclpy.spin_once(node, timeout_sec=0.01)
            for index, pending in list(running.items()):
                worker = workers[index]
                if pending.result is None and pending.acceptance.done():
                    goal_handle = pending.acceptance.result()
                    if not goal_handle.accepted:
                        sys.exit(f'{worker.namespace}/evaluate rejected the episode of seed '
                                 f'{pending.seed}')
                    pending.result = goal_handle.get_result_async()
                if pending.result is not None and pending.result.done():
                    metrics = pending.result.result().result.metrics
                    if expect is not None and metrics.outcome != expect:
                        sys.exit(f'a reference episode ended {metrics.outcome!r}, not {expect}')
                    if results is not None:
                        results.append(metrics)
                    del running[index]
                    continue
                check_worker(worker)
                if time.monotonic() > pending.deadline:
                    awaited = 'the result' if pending.result is not None else 'acceptance'
                    sys.exit(f'no answer from {worker.namespace}/evaluate within {timeout:.0f} '
                             f's: waited for {awaited} of the episode of seed {pending.seed}')
        return time.monotonic() - start
    finally:
        for client in clients:
            client.destroy()


@dataclass
class Pending:
    """An episode sent to a worker: its seed, the goal's acceptance, then its result."""

    seed: int
    acceptance: Any
    deadline: float
    result: Any = None


def check_worker(worker: Worker) -> None:
    death = worker.death()
    if death is not None:
        sys.exit(death)


def episode_timings(log: Path, skip: int) -> list[tuple[float, ...]]:
    """(factor, physics, sensors, metrics, messaging ms) of the node's episodes after ``skip``."""
    return [tuple(map(float, m)) for m in TIMING.findall(log.read_text())][skip:]


def mean(rows: list[tuple[float, ...]], column: int) -> float:
    return sum(row[column] for row in rows) / len(rows)


def factor(rows: list[tuple[float, ...]]) -> str:
    """Mean sim/wall factor and the spread over the episodes (this VM's speed drifts)."""
    factors = [row[0] for row in rows]
    return f'x{mean(rows, 0):.1f} (episodes x{min(factors):.1f}-{max(factors):.1f})'


def controller_compute_ms(environment, episodes: int) -> float:
    """CPU ms per tick of the ND controller's own computation in the benchmark's episodes
    (seeds ``episodes`` down to 1), run in-process as the node runs them: the worker's episode
    config, the map given to the controller (it plans its route on it), the goal check before
    every command (sessgan_evolver.episode_runner, which the re-simulation tests hold to the
    node's episodes)."""
    from sessgan_evolver.episode_runner import EpisodeRunner
    from sessgan_sim.simulator_settings import SimulatorSettings

    spent = [0.0]

    class TimedController:
        """The controller, its decisions timed in this thread's CPU time."""

        def __init__(self, controller) -> None:
            self.controller = controller

        def __getattr__(self, name: str):
            return getattr(self.controller, name)

        def goal_reached(self, *args):
            started = time.thread_time()
            try:
                return self.controller.goal_reached(*args)
            finally:
                spent[0] += time.thread_time() - started

        def compute_command(self, *args):
            started = time.thread_time()
            try:
                return self.controller.compute_command(*args)
            finally:
                spent[0] += time.thread_time() - started

    class TimedRunner(EpisodeRunner):
        def make_controller(self, environment):
            return TimedController(super().make_controller(environment))

    settings = SimulatorSettings(lidar_beams=360, control_rate=20.0)  # REFERENCE_PARAMETERS
    ticks = 0
    with TimedRunner('factory', 'nearness_diagram', settings=settings) as runner:
        for seed in range(episodes, 0, -1):
            ticks += runner.run(environment, seed).metrics['ticks']
    return spent[0] / ticks * 1e3


BUSY_LOOP = ('import time\nstart = time.perf_counter()\ntotal = 0\n'
             'for i in range(15_000_000):\n    total += i\nprint(time.perf_counter() - start)')


def cpu_scaling(graph: ProcessSupervisor, cores: list[int]) -> float:
    """Throughput of a pure-Python busy loop on ``cores`` at once against on the first alone:
    what this machine's cores give two workers before any messaging (virtual CPUs may share a
    physical one)."""
    def run(on: list[int]) -> float:
        children = [graph.start(f'busy{index}', [sys.executable, '-c', BUSY_LOOP], core=core)
                    for index, core in enumerate(on)]
        for child in children:
            child.process.wait(timeout=300)
        seconds = max(float(child.log_tail().split()[-1]) for child in children)
        graph.stop_all()
        for child in children:
            child.log_path.unlink()
        return seconds

    # Best of three: a core of a virtual machine is sometimes slowed by its host.
    return len(cores) * min(run(cores[:1]) for _ in range(3)) / min(run(cores) for _ in range(3))


class PairFigures(NamedTuple):
    wall: float
    """Wall seconds of the measured episodes."""
    timings: list[tuple[float, ...]]
    """(factor, physics, sensors, metrics, messaging ms) of each measured episode."""
    simulator_cpu_ms: float
    controller_cpu_ms: float
    """CPU ms a tick of each process (its process group) over the measured episodes."""


def measure_pair(graph: ProcessSupervisor, node, message, episodes: int, sim_core: int,
                 controller_core: int, batch: bool, timeout: float = EPISODE_TIMEOUT
                 ) -> PairFigures:
    """``episodes`` reference episodes on one worker after a warm-up: their wall seconds,
    the node's timings and the CPU time of the simulator and the controller a tick."""
    worker = start_worker(graph, sim_core, controller_core, batch)
    # The warm-up: imports, discovery, the first build.
    run_episodes(node, [worker], message, 1, timeout=timeout)
    groups = (worker.simulator.process.pid, worker.controller.process.pid)
    cpu_before = [group_cpu_seconds(group) for group in groups]
    results: list = []
    wall = run_episodes(node, [worker], message, episodes, results, timeout=timeout)
    cpu = [group_cpu_seconds(group) - before for group, before in zip(groups, cpu_before)]
    graph.stop_all()
    ticks = sum(metrics.ticks for metrics in results)
    return PairFigures(wall, episode_timings(worker.simulator.log_path, 1),
                       cpu[0] / ticks * 1e3, cpu[1] / ticks * 1e3)


def reference_episode():
    """The factory reference environment and its Environment message."""
    from sessgan_core.ros_conversion import environment_to_msg
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment

    environment = make_environment(load_example_map('factory').cells, 'factory', 'reference')
    return environment, environment_to_msg(environment)


@contextlib.contextmanager
def bench_graph(prefix: str):
    """(client node, supervisor of the processes started); everything stopped on exit."""
    import rclpy

    log_dir = Path(tempfile.mkdtemp(prefix=prefix))
    init_rclpy()  # SIGINT and SIGTERM: KeyboardInterrupt, the graph stopped (run_command)
    node = rclpy.create_node('bench_client')
    graph = ProcessSupervisor(log_dir)
    try:
        yield node, graph
    finally:
        graph.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()
        shutil.rmtree(log_dir, ignore_errors=True)


def main() -> int:
    return run_command(measure)


def measure() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=6)
    parser.add_argument('--floor-ticks', type=int, default=3000)
    parser.add_argument('--timeout', type=float, default=EPISODE_TIMEOUT,
                        help='wall seconds any one wait may take before the benchmark stops, '
                             'naming what it waited for')
    args = parser.parse_args()

    environment, message = reference_episode()
    cores = worker_cores(2)
    first = cores[0] if cores[0] is not None else 0
    two_cores = cores[1] is not None and cores[1] != cores[0]
    if two_cores:  # keep this client's spinning off the measured core
        os.sched_setaffinity(0, {cores[1]})
    with bench_graph('sessgan-bench-') as (node, graph):
        print(f'machine: {os.cpu_count()} cores; factory reference episode, 360-beam scan, '
              f'20 Hz control, ND controller with use_sim_time; {args.episodes} episodes per '
              f'figure after a warm-up')
        floor = measure_floor(graph, first, args.floor_ticks)
        floor_ms = 1e3 / floor.ticks_per_second
        print(f'lockstep floor, bare rclpy (clock + odom + scan out, Twist back), one core: '
              f'{floor_ms:.3f} ms per tick, at most x{50.0 / floor_ms:.0f} real time; CPU time '
              f'{floor.cpu_ms:.3f} ms a tick')
        compute_ms = controller_compute_ms(environment, args.episodes)

        pair = measure_pair(graph, node, message, args.episodes, first, first, True,
                            args.timeout)
        rows = pair.timings
        physics, sensors, metrics, rest = (mean(rows, i) for i in range(1, 5))
        messaging = max(0.0, rest - compute_ms)
        print('simulator + controller on one core, batch scheduling (as campaigns run them):')
        print(f'  sim-time / wall-time factor: {factor(rows)}: '
              f'{mean(rows, 0) / (50.0 / floor_ms):.3f} of the floor')
        print(f'  per tick: physics {physics:.3f} ms, sensors {sensors:.3f} ms, metrics '
              f'{metrics:.3f} ms, controller {compute_ms:.3f} ms, messaging {messaging:.3f} ms '
              f'(x{messaging / floor_ms:.2f} the floor)')
        print(f'  physics + sensors alone: x{50.0 / (physics + sensors):.1f} real time '
              f'(+ metrics: x{50.0 / (physics + sensors + metrics):.1f})')
        cpu_ms = pair.simulator_cpu_ms + pair.controller_cpu_ms
        # CPU time is what a loaded machine distorts least (wall time counts other work).
        print(f'  CPU time a tick: simulator {pair.simulator_cpu_ms:.3f} ms, controller '
              f'{pair.controller_cpu_ms:.3f} ms, together {cpu_ms:.3f} ms: '
              f'{floor.cpu_ms / cpu_ms:.3f} of the floor in CPU time')
        rows = measure_pair(graph, node, message, args.episodes, first, first, False,
                            args.timeout).timings
        print(f'same, default scheduling: {factor(rows)}')
        if two_cores:
            rows = measure_pair(graph, node, message, args.episodes, cores[0], cores[1], True,
                                args.timeout).timings
            print(f'simulator and controller on two cores: {factor(rows)}')

            workers = [start_worker(graph, cores[0], cores[0]),
                       start_worker(graph, cores[1], cores[1])]
            run_episodes(node, workers, message, 2, timeout=args.timeout)
            double = run_episodes(node, workers, message, 2 * args.episodes,
                                  timeout=args.timeout)
            rate_one = args.episodes / pair.wall * 60.0
            rate_two = 2 * args.episodes / double * 60.0
            print(f'throughput: 1 worker {rate_one:.1f} episodes/min, 2 workers '
                  f'{rate_two:.1f} episodes/min (x{rate_two / rate_one:.2f}), each worker and '
                  f'its controller on its own core; a busy loop on both cores against one: '
                  f'x{cpu_scaling(graph, cores):.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
