#!/usr/bin/env python3
"""Benchmark: in-process episodes (sessgan_evolver's EpisodeRunner) per CPU second, per scenario
and robot.

Screening a search method's candidates in process runs thousands of episodes; this prints what
one core gives. For every scenario and every built-in controller that drives a robot there (the
scenario's own, the reference navigator, the tricycle's Nearness-Diagram in the factory), the
scenario's example map with its reference start and goal runs ``--episodes`` episodes
(simulator seeds 1, 2, ...) with the worker's default settings, exactly as a campaign's
in-process evaluator runs them (reset, world build and controller included). Per row:

* episodes per CPU second of this thread (per core: the runner is single-threaded);
* the sim-time / CPU-time factor over all its episodes (``x300``: 300 sim seconds a CPU
  second);
* CPU ms per tick, and the share of it in the simulator's physics, sensors and metrics (the
  rest: the controller, the runner's trace and the episode's reset);
* outcomes.

CPU time of this thread, not wall time: on a shared machine wall time also counts other work.
Usage::

    python tests/benchmarks/bench_in_process.py [--episodes 3] [--scenario factory]
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_controllers.registry import CONTROLLERS  # noqa: E402
from sessgan_core.scenarios import SCENARIOS  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeRunner  # noqa: E402


def controllers_of(scenario: str) -> list[str]:
    """The scenario's own controller first, then every other that drives its robot there."""
    spec = SCENARIOS[scenario]
    others = sorted(name for name, controller in CONTROLLERS.items()
                    if name != spec.controller
                    and controller.drives(controller.robot_in(spec.robot)))
    return [spec.controller, *others]


def measure(scenario: str, controller: str, episodes: int) -> str:
    environment = make_environment(load_example_map(scenario).cells, scenario, 'reference')
    sim_seconds = cpu_seconds = physics = sensors = metrics = 0.0
    ticks = 0
    outcomes: collections.Counter[str] = collections.Counter()
    with EpisodeRunner(scenario, controller, clock=time.thread_time) as runner:
        for seed in range(1, episodes + 1):
            run = runner.run(environment, seed, trace=True)  # as the in-process evaluator
            profile = runner.profile
            sim_seconds += run.metrics['simulation_time']
            cpu_seconds += run.wall_time
            ticks += run.metrics['ticks']
            outcomes[run.metrics['outcome']] += 1
            physics += profile.physics
            sensors += profile.sensors
            metrics += profile.metrics
    per_tick = cpu_seconds / max(1, ticks) * 1e3
    share = (physics + sensors + metrics) / cpu_seconds if cpu_seconds else 0.0
    return (f'| {scenario} | {runner.robot} | {controller} | {episodes / cpu_seconds:.2f} | '
            f'x{sim_seconds / cpu_seconds:.0f} | {per_tick:.3f} | '
            f'{physics / max(1, ticks) * 1e3:.3f} / {sensors / max(1, ticks) * 1e3:.3f} / '
            f'{metrics / max(1, ticks) * 1e3:.3f} ({share:.0%}) | '
            f'{", ".join(f"{name} {count}" for name, count in sorted(outcomes.items()))} |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=3)
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), action='append',
                        help='only this scenario (repeatable; default: all)')
    parser.add_argument('--controller', action='append',
                        help='only this controller (repeatable; default: all of a scenario)')
    args = parser.parse_args()
    print('| scenario | robot | controller | episodes / CPU s | sim / CPU time | CPU ms / tick '
          '| physics / sensors / metrics ms (share) | outcomes |')
    print('|---|---|---|---:|---:|---:|---|---|')
    for scenario in args.scenario or sorted(SCENARIOS):
        for controller in controllers_of(scenario):
            if args.controller and controller not in args.controller:
                continue
            print(measure(scenario, controller, args.episodes), flush=True)


if __name__ == '__main__':
    main()
