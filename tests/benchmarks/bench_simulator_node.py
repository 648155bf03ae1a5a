"""Benchmark: the simulator node in lockstep with a controller in a separate process.

Prints, for the factory reference episode (example map, 360-beam scan, 20 Hz control, Nearness
Diagram controller in its own process):
* the sim-time / wall-time factor of the node (simulator pinned to one core, the controller on
  the other when there are two), with the time per tick split into physics, sensors, metrics
  and messaging (the node's own log line);
* throughput of 2 workers (each with its own controller) against 1, in episodes per minute.

Run after `source setup.bash`:  python tests/benchmarks/bench_simulator_node.py [--episodes N]
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randrange(10, 100)))

TIMING = re.compile(r'\(x([\d.]+) real time\); per tick ms: physics=([\d.]+) sensors=([\d.]+) '
                    r'metrics=([\d.]+) messaging=([\d.]+)')


def pinned(command: list[str], core: int | None) -> list[str]:
    if core is None or shutil.which('taskset') is None:
        return command
    return ['taskset', '-c', str(core)] + command


class Graph:
    """Simulator workers and controllers, each its own process group."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.processes: list[subprocess.Popen] = []

    def start(self, name: str, command: list[str]) -> Path:
        log = self.log_dir / f'{name}.log'
        with open(log, 'wb') as handle:
            self.processes.append(subprocess.Popen(command, stdout=handle,
                                                   stderr=subprocess.STDOUT,
                                                   start_new_session=True))
        return log

    def stop(self) -> None:
        for process in self.processes:
            try:
                os.killpg(process.pid, 2)
            except ProcessLookupError:
                pass
        for process in self.processes:
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, 9)


def start_worker(graph: Graph, index: int, sim_core: int | None,
                 controller_core: int | None) -> Path:
    namespace = f'/bench{index}'
    args = ['--ros-args', '-r', f'__ns:={namespace}']
    log = graph.start(f'sim{index}', pinned(['ros2', 'run', 'sessgan_sim', 'simulator', *args,
                                             '-p', 'lidar_beams:=360', '-p', 'control_rate:=20.0'],
                                            sim_core))
    graph.start(f'ctl{index}', pinned(['ros2', 'run', 'sessgan_controllers', 'nearness_diagram',
                                       *args, '-p', 'use_sim_time:=true'], controller_core))
    return log


def run_episodes(node, namespaces: list[str], environment_msg, episodes: int) -> float:
    """Run ``episodes`` reference episodes spread over the workers; return wall seconds."""
    import rclpy
    from rclpy.action import ActionClient

    from sessgan_interfaces.action import EvaluateEnvironment

    clients = [ActionClient(node, EvaluateEnvironment, f'{ns}/evaluate') for ns in namespaces]
    for client in clients:
        if not client.wait_for_server(timeout_sec=60):
            sys.exit('a simulator worker did not come up')
    remaining = episodes
    running: dict[int, object] = {}
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
                del running[index]
    return time.monotonic() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=4)
    args = parser.parse_args()

    import rclpy

    from sessgan_gen.navigation import make_environment
    from sessgan_gen.ros_conversion import environment_to_msg
    from sessgan_gen.token_map import load_example_map

    environment = make_environment(load_example_map('factory').cells, 'factory', 'reference')
    message = environment_to_msg(environment)
    cores = os.cpu_count() or 1
    log_dir = Path(tempfile.mkdtemp(prefix='sessgan-bench-'))
    rclpy.init()
    node = rclpy.create_node('bench_client')
    graph = Graph(log_dir)
    try:
        # One worker: the simulator on core 0, its controller on core 1.
        log = start_worker(graph, 0, 0, 1 if cores > 1 else 0)
        run_episodes(node, ['/bench0'], message, 1)  # warm-up: imports, discovery
        single = run_episodes(node, ['/bench0'], message, args.episodes)
        timings = [tuple(map(float, m)) for m in TIMING.findall(log.read_text())][1:]
        factor = sum(t[0] for t in timings) / len(timings)
        split = [sum(t[i] for t in timings) / len(timings) for i in range(1, 5)]
        print(f'factory reference episode, lockstep, simulator on one core, '
              f'{len(timings)} episodes (after one warm-up)')
        print(f'  sim-time / wall-time factor: x{factor:.1f}')
        print('  per tick: physics {:.3f} ms, sensors {:.3f} ms, metrics {:.3f} ms, '
              'messaging {:.3f} ms'.format(*split))
        core_only = 50.0 / (split[0] + split[1] + split[2])
        print(f'  physics + sensors + metrics alone: x{core_only:.1f} real time')

        # Two workers against one, on the same machine.
        start_worker(graph, 1, None, None)
        double = run_episodes(node, ['/bench0', '/bench1'], message, 2 * args.episodes)
        rate_one = args.episodes / single * 60.0
        rate_two = 2 * args.episodes / double * 60.0
        print(f'throughput: 1 worker {rate_one:.1f} episodes/min, 2 workers {rate_two:.1f} '
              f'episodes/min (x{rate_two / rate_one:.2f}) on {cores} cores')
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
        shutil.rmtree(log_dir, ignore_errors=True)


if __name__ == '__main__':
    main()
