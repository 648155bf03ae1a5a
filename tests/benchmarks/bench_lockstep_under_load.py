"""Lockstep under load: does a worker lose a tick's message when every core is saturated?

The simulator reads cmd_vel best effort (bench_simulator_node.py shows why). This runs the factory
reference episode ``--episodes`` times on one worker (simulator and Nearness-Diagram controller on
one core, as campaigns start them) while ``--load`` busy loops keep every core busy, and prints
the outcomes and tick counts: a lost command would end an episode controller_unresponsive, and
the same seeds must give the same ticks with and without load.

Run after `source setup.bash`:
    python tests/benchmarks/bench_lockstep_under_load.py [--episodes 40] [--load 2] [--default]
"""

from __future__ import annotations

import argparse
import collections
import subprocess
import sys
import time

from bench_simulator_node import bench_graph, reference_episode, run_episodes, start_worker

from sessgan_core.ros_spin import run_command
from sessgan_evolver.process_supervisor import worker_cores


def main() -> int:
    return run_command(measure)


def measure() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=40)
    parser.add_argument('--load', type=int, default=2, help='busy-loop processes')
    parser.add_argument('--default', action='store_true',
                        help='default scheduling instead of batch')
    args = parser.parse_args()

    _, message = reference_episode()
    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(args.load)]
    try:
        with bench_graph('sessgan-load-') as (node, graph):
            core = worker_cores(1)[0] or 0
            worker = start_worker(graph, core, core, batch=not args.default)
            results: list = []
            start = time.monotonic()
            run_episodes(node, [worker], message, args.episodes, results, expect=None)
            wall = time.monotonic() - start
    finally:
        for process in busy:
            process.kill()
    for metrics in results:
        if metrics.outcome == 'controller_unresponsive':
            print(f'{metrics.environment_id}: {metrics.detail}')
    outcomes = collections.Counter(metrics.outcome for metrics in results)
    print(f'{args.episodes} episodes with {args.load} busy loops, '
          f'{"default" if args.default else "batch"} scheduling: {dict(outcomes)}, '
          f'{sum(metrics.ticks for metrics in results)} ticks in {wall:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
