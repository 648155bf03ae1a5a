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
* CPU ms per tick, and the share of it in the simulator's physics, sensors and metrics, the
  episode's reset and the controller's decisions (the rest: the runner's trace);
* the floor measured in the same run: pybullet's ``stepSimulation`` alone, as many calls a
  tick as the physics rate asks, in the episode's own world, and the episodes' CPU time a
  tick over it;
* outcomes.

``--baseline-tree DIR`` (a checkout of another commit, e.g. ``git worktree add /tmp/base
HEAD~3``) measures every row with that tree's packages too, in a child process, alternating
which goes first over ``--rounds`` rounds, and prints this tree's CPU time a tick over the
baseline's (medians of the rounds).

CPU time of this thread, not wall time: on a shared machine wall time also counts other work.
Usage::

    python tests/benchmarks/bench_in_process.py [--episodes 3] [--scenario factory]
        [--controller nearness_diagram] [--baseline-tree DIR --rounds 3]
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

# The packages of this checkout, or of the tree a --baseline-tree child measures.
ROOT = Path(os.environ.get('SESSGAN_BENCH_TREE') or Path(__file__).resolve().parents[2])
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

import pybullet as p  # noqa: E402

from sessgan_controllers.registry import CONTROLLERS  # noqa: E402
from sessgan_core.scenarios import SCENARIOS  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeRunner  # noqa: E402

PARTS = ('physics', 'sensors', 'metrics', 'reset', 'controller')


def controllers_of(scenario: str) -> list[str]:
    """The scenario's own controller first, then every other that drives its robot there."""
    spec = SCENARIOS[scenario]
    others = sorted(name for name, controller in CONTROLLERS.items()
                    if name != spec.controller
                    and controller.drives(controller.robot_in(spec.robot)))
    return [spec.controller, *others]


def step_floor(runner: EpisodeRunner, calls: int = 2000) -> float:
    """CPU seconds of the physics steps of one tick, pybullet's stepSimulation alone, in the
    world the runner's last episode left."""
    episode = runner._episode  # noqa: SLF001 (the floor is timed in the episode's own world)
    assert episode is not None
    client = episode._world.client  # noqa: SLF001
    started = time.thread_time()
    for _ in range(calls):
        p.stepSimulation(physicsClientId=client)
    steps = runner.episode_config(0).physics_steps_per_tick
    return (time.thread_time() - started) / calls * steps


def measure(scenario: str, controller: str, episodes: int) -> dict:
    """CPU seconds (total and per part), sim seconds, ticks and outcomes of the episodes."""
    environment = make_environment(load_example_map(scenario).cells, scenario, 'reference')
    totals: collections.Counter[str] = collections.Counter()
    outcomes: collections.Counter[str] = collections.Counter()
    with EpisodeRunner(scenario, controller, clock=time.thread_time) as runner:
        for seed in range(1, episodes + 1):
            run = runner.run(environment, seed, trace=True)  # as the in-process evaluator
            totals['sim'] += run.metrics['simulation_time']
            totals['cpu'] += run.wall_time
            totals['ticks'] += run.metrics['ticks']
            outcomes[run.metrics['outcome']] += 1
            for part in PARTS:  # a baseline tree's profile may lack the later parts
                totals[part] += getattr(runner.profile, part, math.nan)
        floor = step_floor(runner)
    return {'robot': runner.robot, 'controller': controller, 'totals': dict(totals),
            'floor': floor,
            'outcomes': dict(outcomes)}


def in_child(tree: Path, scenario: str, controller: str, episodes: int) -> dict:
    """:func:`measure` with ``tree``'s packages, in a child process of its own."""
    child = subprocess.run(
        [sys.executable, __file__, '--child', '--scenario', scenario, '--controller',
         controller, '--episodes', str(episodes)],
        env={**os.environ, 'SESSGAN_BENCH_TREE': str(tree)}, capture_output=True, text=True,
        timeout=1800)
    if child.returncode:
        sys.exit(f'the measurement with tree {tree} failed:\n{child.stderr[-2000:]}')
    return json.loads(child.stdout.strip().splitlines()[-1])


def row(scenario: str, result: dict, episodes: int, versus: str | None = None) -> str:
    """A table row; ``versus``: the CPU vs baseline cell (None: no such column)."""
    totals = result['totals']
    cpu, ticks = totals['cpu'], max(1, totals['ticks'])
    per_tick = cpu / ticks
    parts = ' / '.join(f'{totals[part] / ticks * 1e3:.3f}' for part in PARTS)
    floor = result['floor']
    ratio = '' if versus is None else f' {versus} |'
    return (f"| {scenario} | {result['robot']} | {result['controller']} | "
            f'{episodes / cpu:.2f} | x{totals["sim"] / cpu:.0f} | {per_tick * 1e3:.3f} | '
            f'{parts} | {floor * 1e3:.3f} (x{per_tick / floor:.1f}) |{ratio} '
            f'{", ".join(f"{name} {count}" for name, count in sorted(result["outcomes"].items()))}'
            f' |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--episodes', type=int, default=3)
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), action='append',
                        help='only this scenario (repeatable; default: all)')
    parser.add_argument('--controller', action='append',
                        help='only this controller (repeatable; default: all of a scenario)')
    parser.add_argument('--baseline-tree', type=Path,
                        help='a checkout whose packages are measured too, for the ratio')
    parser.add_argument('--rounds', type=int, default=3,
                        help='with --baseline-tree: alternated measurements of each tree')
    parser.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.scenario[0], args.controller[0], args.episodes)))
        return
    tree = args.baseline_tree
    if tree is not None and not (tree / 'sessgan_sim').is_dir():
        parser.error(f'--baseline-tree {tree}: not a checkout of this project (no sessgan_sim)')
    print(f'load average {os.getloadavg()[0]:.1f}' + (f'; baseline tree {tree}' if tree else ''))
    print('| scenario | robot | controller | episodes / CPU s | sim / CPU time | CPU ms / tick '
          '| physics / sensors / metrics / reset / controller ms a tick '
          '| stepSimulation floor ms a tick (CPU over it) |'
          + (' CPU vs baseline |' if tree else '') + ' outcomes |')
    print('|---|---|---|---:|---:|---:|---|---|' + ('---:|' if tree else '') + '---|')
    for scenario in args.scenario or sorted(SCENARIOS):
        for controller in controllers_of(scenario):
            if args.controller and controller not in args.controller:
                continue
            if tree is None:
                result = measure(scenario, controller, args.episodes)
                print(row(scenario, result, args.episodes), flush=True)
                continue
            # Both trees in fresh child processes, alike: alternating which goes first.
            ours, theirs = [], []
            for round_ in range(args.rounds):
                order = (True, False) if round_ % 2 == 0 else (False, True)
                for this_tree in order:
                    results = ours if this_tree else theirs
                    results.append(in_child(ROOT if this_tree else tree, scenario, controller,
                                            args.episodes))
            cpu_a_tick = [each['totals']['cpu'] / each['totals']['ticks'] for each in theirs]
            base = statistics.median(cpu_a_tick)
            # The round whose CPU time a tick is the median's.
            cpu_ours = [each['totals']['cpu'] / each['totals']['ticks'] for each in ours]
            median_ours = ours[cpu_ours.index(statistics.median_low(cpu_ours))]
            median_theirs = theirs[cpu_a_tick.index(statistics.median_low(cpu_a_tick))]
            versus = statistics.median(cpu_ours) / base
            print(row(scenario, median_ours, args.episodes, f'{versus:.3f}'), flush=True)
            print(row(f'{scenario} (baseline)', median_theirs, args.episodes, '1'), flush=True)


if __name__ == '__main__':
    main()
