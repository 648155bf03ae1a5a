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
import os
import random
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

from sessgan_evolver.process_supervisor import ProcessSupervisor, worker_cores
from sessgan_gen.ros_spin import init_rclpy, run_command

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randrange(10, 100)))

HERE = Path(__file__).resolve().parent
TIMING = re.compile(r'\(x([\d.]+) real time\); per tick ms: physics=([\d.]+) sensors=([\d.]+) '
                    r'metrics=([\d.]+) messaging=([\d.]+)')
REFERENCE_PARAMETERS = ['-p', 'lidar_beams:=360', '-p', 'control_rate:=20.0']


def measure_floor(graph: ProcessSupervisor, core: int, ticks: int) -> float:
    """Lockstep ticks per second of bare rclpy with the reference messages, on ``core``, as
    batch processes (like the campaign's workers)."""
    script = str(HERE / 'lockstep_floor.py')
    ns = ['--ros-args', '-r', '__ns:=/floor']
    graph.start('floor_controller', [sys.executable, script, '--role', 'controller', *ns],
                core=core, batch=True)
    sim = graph.start('floor_sim', [sys.executable, script, '--role', 'sim', '--ticks',
                                    str(ticks), *ns], core=core, batch=True)
    sim.process.wait(timeout=300)
    found = re.search(r'ticks_per_second=([\d.]+)', sim.log_tail())
    graph.stop_all()
    if not found:
        sys.exit(f'the lockstep floor failed:\n{sim.log_tail()}')
    return float(found.group(1))


def start_worker(graph: ProcessSupervisor, index: int, sim_core: int, controller_core: int,
                 batch: bool = True) -> Path:
    """A simulator worker /bench<index> and its ND controller; returns the simulator's log."""
    args = ['--ros-args', '-r', f'__ns:=/bench{index}']
    simulator = graph.start(f'sim{index}', ['ros2', 'run', 'sessgan_sim', 'simulator', *args,
                                            *REFERENCE_PARAMETERS], core=sim_core, batch=batch)
    graph.start(f'ctl{index}', ['ros2', 'run', 'sessgan_controllers', 'nearness_diagram', *args,
                                '-p', 'use_sim_time:=true'], core=controller_core, batch=batch)
    return simulator.log_path


def run_episodes(node, namespaces: list[str], environment_msg, episodes: int,
                 results: list | None = None, expect: str | None = 'goal_reached') -> float:
    """Run ``episodes`` reference episodes (seeds ``episodes`` down to 1) spread over the
    workers; return wall seconds. Each episode's metrics go to ``results``; an outcome other
    than ``expect`` ends the benchmark."""
    import rclpy
    from rclpy.action import ActionClient

    from sessgan_interfaces.action import EvaluateEnvironment

    clients = [ActionClient(node, EvaluateEnvironment, f'{ns}/evaluate') for ns in namespaces]
    for client in clients:
        if not client.wait_for_server(timeout_sec=60):
            sys.exit('a simulator worker did not come up')
    remaining = episodes
    running: dict[int, list] = {}
    start = time.monotonic()
    while remaining or running:
        for index, client in enumerate(clients):
            if index not in running and remaining:
                goal = EvaluateEnvironment.Goal(environment=environment_msg, seed=remaining)
                running[index] = [client.send_goal_async(goal), None]
                remaining -= 1
        rclpy.spin_once(node, timeout_sec=0.01)
        for index, state in list(running.items()):
            if state[1] is None and state[0].done():
                state[1] = state[0].result().get_result_async()
            if state[1] is not None and state[1].done():
                metrics = state[1].result().result.metrics
                if expect is not None and metrics.outcome != expect:
                    sys.exit(f'a reference episode ended {metrics.outcome!r}, not {expect}')
                if results is not None:
                    results.append(metrics)
                del running[index]
    for client in clients:
        client.destroy()
    return time.monotonic() - start


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
                 controller_core: int, batch: bool) -> tuple[float, list[tuple[float, ...]]]:
    """Wall seconds of ``episodes`` reference episodes on one worker, and the node's timings."""
    log = start_worker(graph, 0, sim_core, controller_core, batch)
    run_episodes(node, ['/bench0'], message, 1)  # warm-up: imports, discovery, first build
    wall = run_episodes(node, ['/bench0'], message, episodes)
    graph.stop_all()
    timings = episode_timings(log, 1)
    log.unlink()  # logs are appended to: the next measurement starts a fresh one
    return wall, timings


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

        single, rows = measure_pair(graph, node, message, args.episodes, first, first, True)
        physics, sensors, metrics, rest = (mean(rows, i) for i in range(1, 5))
        messaging = max(0.0, rest - compute_ms)
        print('simulator + controller on one core, batch scheduling (as campaigns run them):')
        print(f'  sim-time / wall-time factor: {factor(rows)}')
        print(f'  per tick: physics {physics:.3f} ms, sensors {sensors:.3f} ms, metrics '
              f'{metrics:.3f} ms, controller {compute_ms:.3f} ms, messaging {messaging:.3f} ms '
              f'(x{messaging / floor_ms:.2f} the floor)')
        print(f'  physics + sensors alone: x{50.0 / (physics + sensors):.1f} real time '
              f'(+ metrics: x{50.0 / (physics + sensors + metrics):.1f})')
        _, rows = measure_pair(graph, node, message, args.episodes, first, first, False)
        print(f'same, default scheduling: {factor(rows)}')
        if two_cores:
            _, rows = measure_pair(graph, node, message, args.episodes, cores[0], cores[1], True)
            print(f'simulator and controller on two cores: {factor(rows)}')

            start_worker(graph, 0, cores[0], cores[0])
            start_worker(graph, 1, cores[1], cores[1])
            run_episodes(node, ['/bench0', '/bench1'], message, 2)
            double = run_episodes(node, ['/bench0', '/bench1'], message, 2 * args.episodes)
            rate_one = args.episodes / single * 60.0
            rate_two = 2 * args.episodes / double * 60.0
            print(f'throughput: 1 worker {rate_one:.1f} episodes/min, 2 workers '
                  f'{rate_two:.1f} episodes/min (x{rate_two / rate_one:.2f}), each worker and '
                  f'its controller on its own core; a busy loop on both cores against one: '
                  f'x{cpu_scaling(graph, cores):.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
