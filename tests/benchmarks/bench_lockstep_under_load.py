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
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_simulator_node import ProcessSupervisor, start_worker, worker_cores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=40)
    parser.add_argument('--load', type=int, default=2, help='busy-loop processes')
    parser.add_argument('--default', action='store_true',
                        help='default scheduling instead of batch')
    args = parser.parse_args()

    import rclpy
    from rclpy.action import ActionClient

    from sessgan_gen.navigation import make_environment
    from sessgan_gen.ros_conversion import environment_to_msg
    from sessgan_gen.token_map import load_example_map
    from sessgan_interfaces.action import EvaluateEnvironment

    message = environment_to_msg(
        make_environment(load_example_map('factory').cells, 'factory', 'reference'))
    log_dir = Path(tempfile.mkdtemp(prefix='sessgan-load-'))
    rclpy.init()
    node = rclpy.create_node('load_client')
    graph = ProcessSupervisor(log_dir)
    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(args.load)]
    try:
        core = worker_cores(1)[0] or 0
        start_worker(graph, 0, core, core, batch=not args.default)
        client = ActionClient(node, EvaluateEnvironment, '/bench0/evaluate')
        if not client.wait_for_server(timeout_sec=60):
            sys.exit('the simulator worker did not come up')
        outcomes: collections.Counter = collections.Counter()
        ticks = 0
        start = time.monotonic()
        for seed in range(args.episodes):
            sent = client.send_goal_async(EvaluateEnvironment.Goal(environment=message, seed=seed))
            rclpy.spin_until_future_complete(node, sent)
            result = sent.result().get_result_async()
            rclpy.spin_until_future_complete(node, result)
            metrics = result.result().result.metrics
            outcomes[metrics.outcome] += 1
            ticks += metrics.ticks
            if metrics.outcome == 'controller_unresponsive':
                print(f'episode {seed}: {metrics.detail}', flush=True)
        print(f'{args.episodes} episodes with {args.load} busy loops, '
              f'{"default" if args.default else "batch"} scheduling: {dict(outcomes)}, '
              f'{ticks} ticks in {time.monotonic() - start:.1f} s')
    finally:
        for process in busy:
            process.kill()
        graph.stop_all()
        node.destroy_node()
        rclpy.try_shutdown()
        shutil.rmtree(log_dir, ignore_errors=True)


if __name__ == '__main__':
    main()
