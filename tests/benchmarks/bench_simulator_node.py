"""Benchmark: the simulator node in lockstep with a controller in a separate process.

The factory reference episode (example map, 360-beam scan, 20 Hz control, the Nearness-Diagram
controller in its own process with use_sim_time, so clock, odom and scan reach it every tick).
Prints:
* the floor: bare rclpy processes exchanging the same messages per tick with no simulation and
  no controller logic (lockstep_floor.py), on one core, measured first in the same run;
* the simulator and its controller on one core as batch processes (how campaigns start them):
  the sim-time / wall-time factor, and the time per tick split into physics, sensors, metrics
  (the node's own timing), the controller's computation (the same episode run in-process) and
  messaging (the rest: ROS 2 publishing, delivery and callbacks on both sides, against the
  floor);
* the same pair with default scheduling, and on two cores (one process per core);
* throughput of 2 workers against 1, each worker's pair on its own core, in episodes per minute,
  next to the same ratio for a pure-Python busy loop (the machine's own scaling).

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
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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


def measure_floor(graph: ProcessSupervisor, core: int, ticks: int) -> float:
    """Lockstep ticks per second of bare rclpy with the reference messages, on ``core``, as
    batch processes (like the campaign's workers)."""
    script = str(HERE / 'lockstep_floor.py')
    number = next(_worker_numbers)
    ns = ['--ros-args', '-r', f'__ns:=/floor{number}']
    graph.start(f'floor_controller{number}', [sys.executable, script, '--role', 'controller',
                                              *ns], core=core, batch=True)
    sim = graph.start(f'floor_sim{number}', [sys.executable, script, '--role', 'sim', '--ticks',
                                             str(ticks), *ns], core=core, batch=True)
    try:
        sim.process.wait(timeout=FLOOR_TIMEOUT)
    except subprocess.TimeoutExpired:
        sys.exit(f'the lockstep floor did not finish {ticks} ticks within {FLOOR_TIMEOUT:.0f} '
                 f's:\n{sim.log_tail()}')
    found = re.search(r'ticks_per_second=([\d.]+)', sim.log_tail())
    graph.stop_all()
    if not found:
        sys.exit(f'the lockstep floor failed:\n{sim.log_tail()}')
    return float(found.group(1))


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


def controller_compute_ms(environment) -> float:
    """CPU ms per tick of the ND controller's own computation on the reference episode,
    run in-process (the simulator core stepping, the controller deciding, no ROS)."""
    from sessgan_controllers.registry import get_controller
    from sessgan_controllers.types import Goal, observed
    from sessgan_sim.episode import Episode, EpisodeConfig
    from sessgan_sim.sensors import LidarConfig

    spec = get_controller('nearness_diagram')
    controller = spec.make(spec.config_type())
    goal = Goal(environment.goal.x, environment.goal.y)
    spent, ticks = 0.0, 0
    with Episode() as episode:
        observation = episode.reset(environment, EpisodeConfig(
            lidar=LidarConfig(beams=360), control_rate_hz=20.0, seed=1))
        while not episode.done:
            started = time.thread_time()
            command = controller.compute_command(*observed(observation), goal)
            spent += time.thread_time() - started
            ticks += 1
            observation = episode.step(command.values()).observation
    return spent / ticks * 1e3


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


def measure_pair(graph: ProcessSupervisor, node, message, episodes: int, sim_core: int,
                 controller_core: int, batch: bool, timeout: float = EPISODE_TIMEOUT
                 ) -> tuple[float, list[tuple[float, ...]]]:
    """Wall seconds of ``episodes`` reference episodes on one worker, and the node's timings."""
    worker = start_worker(graph, sim_core, controller_core, batch)
    # The warm-up: imports, discovery, the first build.
    run_episodes(node, [worker], message, 1, timeout=timeout)
    wall = run_episodes(node, [worker], message, episodes, timeout=timeout)
    graph.stop_all()
    return wall, episode_timings(worker.simulator.log_path, 1)


def reference_episode():
    """The factory reference environment and its Environment message."""
    from sessgan_gen.navigation import make_environment
    from sessgan_gen.ros_conversion import environment_to_msg
    from sessgan_gen.token_map import load_example_map

    environment = make_environment(load_example_map('factory').cells, 'factory', 'reference')
    return environment, environment_to_msg(environment)


@contextlib.contextmanager
def bench_graph(prefix: str):
    """(client node, supervisor of the processes started); everything stopped on exit."""
    import rclpy

    log_dir = Path(tempfile.mkdtemp(prefix=prefix))
    rclpy.init()
    node = rclpy.create_node('bench_client')
    graph = ProcessSupervisor(log_dir)
    try:
        yield node, graph
    finally:
        graph.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()
        shutil.rmtree(log_dir, ignore_errors=True)


def main() -> None:
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
        floor_ms = 1e3 / measure_floor(graph, first, args.floor_ticks)
        print(f'lockstep floor, bare rclpy (clock + odom + scan out, Twist back), one core: '
              f'{floor_ms:.3f} ms per tick, at most x{50.0 / floor_ms:.0f} real time')
        compute_ms = controller_compute_ms(environment)

        single, rows = measure_pair(graph, node, message, args.episodes, first, first, True,
                                   args.timeout)
        physics, sensors, metrics, rest = (mean(rows, i) for i in range(1, 5))
        messaging = max(0.0, rest - compute_ms)
        print('simulator + controller on one core, batch scheduling (as campaigns run them):')
        print(f'  sim-time / wall-time factor: {factor(rows)}')
        print(f'  per tick: physics {physics:.3f} ms, sensors {sensors:.3f} ms, metrics '
              f'{metrics:.3f} ms, controller {compute_ms:.3f} ms, messaging {messaging:.3f} ms '
              f'(x{messaging / floor_ms:.2f} the floor)')
        print(f'  physics + sensors alone: x{50.0 / (physics + sensors):.1f} real time '
              f'(+ metrics: x{50.0 / (physics + sensors + metrics):.1f})')
        _, rows = measure_pair(graph, node, message, args.episodes, first, first, False,
                               args.timeout)
        print(f'same, default scheduling: {factor(rows)}')
        if two_cores:
            _, rows = measure_pair(graph, node, message, args.episodes, cores[0], cores[1], True,
                                   args.timeout)
            print(f'simulator and controller on two cores: {factor(rows)}')

            workers = [start_worker(graph, cores[0], cores[0]),
                       start_worker(graph, cores[1], cores[1])]
            run_episodes(node, workers, message, 2, timeout=args.timeout)
            double = run_episodes(node, workers, message, 2 * args.episodes,
                                  timeout=args.timeout)
            rate_one = args.episodes / single * 60.0
            rate_two = 2 * args.episodes / double * 60.0
            print(f'throughput: 1 worker {rate_one:.1f} episodes/min, 2 workers '
                  f'{rate_two:.1f} episodes/min (x{rate_two / rate_one:.2f}), each worker and '
                  f'its controller on its own core; a busy loop on both cores against one: '
                  f'x{cpu_scaling(graph, cores):.2f}')


if __name__ == '__main__':
    main()
