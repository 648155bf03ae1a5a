#!/usr/bin/env python3
"""Benchmark: the reference navigator on fresh generated maps of every scenario, in-process.

For each scenario, ``--maps`` maps are sampled from the shipped generator checkpoint (seeds
``--first-seed`` on; seeds used for tuning were 800000-800199, so the default range 900000 on
is fresh), and the reference navigator drives the scenario's robot (its ``robot`` parameter
set accordingly) through one episode per valid (``feasible``) map on the ROS-free simulator
core, with the scenario's defaults (dummy agents, time limit, lidar, 20 Hz control). The
episode seed is the map seed. Prints per scenario:

* valid maps out of the sampled ones (only valid maps count below);
* success: goal reached with no fault collision (``fault_collisions`` where the episode
  metrics have it; otherwise every contact except an agent driving into the robot while it
  stood still, told apart here from the agents' positions and the robot's speed);
* collisions per episode (fault collisions, and all collisions);
* the other outcomes (stuck, timeout, collision limit) in %;
* mean simulation time of all episodes and of the successful ones;
* the controller's CPU time per step, and each failure's map seed and outcome.

Run after ``source setup.bash``::

    python tests/benchmarks/bench_reference_navigator.py [--maps 100] [--scenarios factory ...]
        [--first-seed 900000] [--jobs 2]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_controllers.controller_interface import Goal, MapData, observed  # noqa: E402
from sessgan_controllers.registry import get_controller  # noqa: E402
from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_gen.environment_sampler import EnvironmentSampler  # noqa: E402
from sessgan_sim.episode import Episode, EpisodeConfig  # noqa: E402
from sessgan_sim.metrics import EpisodeMetrics  # noqa: E402

SCENARIOS = ('factory', 'racetrack', 'drone')


@dataclass(frozen=True)
class Result:
    """One episode's figures."""

    environment_id: str
    seed: int
    outcome: str
    collisions: int
    fault_collisions: int
    simulation_time: float
    controller_seconds: float
    steps: int
    detail: str
    contacts: tuple[str, ...] = ()
    """What each new contact touched (see :func:`contact_kind`)."""

    @property
    def success(self) -> bool:
        return self.outcome == 'goal_reached' and self.fault_collisions == 0


def fault_collisions(metrics: EpisodeMetrics, contacts: list[str]) -> int:
    """The controller's collisions: the episode's ``fault_collisions`` where its metrics have
    them; else the contacts of :func:`contact_kind` other than an agent driving into the robot
    standing still (the attribution of ARCHITECTURE.md, approximated here)."""
    if hasattr(metrics, 'fault_collisions'):
        return int(metrics.fault_collisions)
    return sum(1 for kind in contacts if kind != 'agent, still')


def run_episode(environment: Environment, overrides: dict[str, object]) -> Result:
    """One episode of the reference navigator on ``environment`` (in-process, lockstep)."""
    scenario = get_scenario(environment.scenario)
    controller = get_controller('reference_navigator').make(robot=scenario.robot, **overrides)
    controller.set_map(MapData.of(environment))
    goal = Goal(environment.goal.x, environment.goal.y)
    spent = 0.0
    steps = 0
    contacts: list[str] = []
    with Episode() as episode:
        observation = episode.reset(environment, EpisodeConfig(seed=int(environment.seed)))
        done = episode.done
        while not done:
            started = time.thread_time()
            scan, state = observed(observation)
            command = controller.compute_command(scan, state, goal)
            spent += time.thread_time() - started
            steps += 1
            observation, done, _ = episode.step(command.values())
            if episode.metrics().collisions > len(contacts):
                contacts.append(contact_kind(episode, state.speed))
        metrics = episode.metrics()
    outcome = metrics.outcome.value if metrics.outcome is not None else 'running'
    return Result(environment.id, int(environment.seed), outcome, int(metrics.collisions),
                  fault_collisions(metrics, contacts), float(metrics.simulation_time), spent,
                  steps, metrics.detail, tuple(contacts))


STILL_SPEED = 0.05
"""m/s: a robot slower than this when an agent touches it was standing still."""


def contact_kind(episode: Episode, speed_before: float) -> str:
    """'static' (a wall, the track's edge) or, when a dummy agent is within touching distance,
    'agent, moving' or 'agent, still' (the robot's speed in m/s at the start of the tick in
    which the contact began)."""
    agents = episode.agents
    if len(agents.positions):
        x, y = episode.robot.position
        reach = episode.robot.footprint_radius + agents.config.radius + 0.02
        if np.hypot(agents.positions[:, 0] - x, agents.positions[:, 1] - y).min() <= reach:
            return 'agent, still' if speed_before < STILL_SPEED else 'agent, moving'
    return 'static'


def _run_packed(item: tuple[Environment, dict[str, object]]) -> Result:
    return run_episode(*item)


def percent(count: int, total: int) -> str:
    return f'{100.0 * count / total:5.1f} %' if total else '    - '


def parse_overrides(items: list[str]) -> dict[str, object]:
    """``name=value`` pairs as navigator parameter overrides (numbers where they parse)."""
    overrides: dict[str, object] = {}
    for item in items:
        name, _, text = item.partition('=')
        value: object = text
        for kind in (int, float):
            try:
                value = kind(text)
                break
            except ValueError:
                continue
        overrides[name] = value
    return overrides


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--maps', type=int, default=100, help='maps sampled per scenario')
    parser.add_argument('--first-seed', type=int, default=900000, help='seed of the first map')
    parser.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument('--jobs', type=int, default=1, help='episodes run in parallel')
    parser.add_argument('--set', nargs='*', default=[], metavar='NAME=VALUE',
                        help='navigator parameter overrides, e.g. max_speed=0.8')
    args = parser.parse_args(argv)
    overrides = parse_overrides(args.set)

    print(f'machine: {platform.machine()}, {os.cpu_count()} cores, load average '
          f'{os.getloadavg()[0]:.2f}; python {platform.python_version()}; {args.jobs} job(s); '
          f'maps {args.first_seed}..{args.first_seed + args.maps - 1} per scenario'
          + (f'; overrides {overrides}' if overrides else ''))
    sampler = EnvironmentSampler()
    rows = []
    for scenario in args.scenarios:
        started = time.perf_counter()
        seeds = list(range(args.first_seed, args.first_seed + args.maps))
        environments = sampler.sample(seeds, scenario=scenario)
        valid = [environment for environment in environments if environment.feasible]
        items = [(environment, overrides) for environment in valid]
        if args.jobs > 1:
            with ProcessPoolExecutor(args.jobs) as pool:
                results = list(pool.map(_run_packed, items, chunksize=1))
        else:
            results = [_run_packed(item) for item in items]
        wall = time.perf_counter() - started
        rows.append((scenario, len(environments), results, wall))
        print_failures(scenario, results)
    print_table(rows)
    return 0


def print_failures(scenario: str, results: list[Result]) -> None:
    failures = [result for result in results if not result.success]
    print(f'\n{scenario}: {len(failures)} failure(s) of {len(results)} valid maps')
    for result in failures:
        touched = f' [{"; ".join(result.contacts)}]' if result.contacts else ''
        print(f'  seed {result.seed}: {result.outcome}, {result.fault_collisions} fault '
              f'collision(s) ({result.collisions} in all{touched}), '
              f'{result.simulation_time:.1f} s: {result.detail}')


def print_table(rows: list[tuple[str, int, list[Result], float]]) -> None:
    print()
    print('| scenario | valid maps | success | fault collisions / episode (all) | stuck | '
          'timeout | collision limit | mean sim time (successes) | controller ms/step | '
          'wall s |')
    print('|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
    for scenario, sampled, results, wall in rows:
        total = len(results)
        outcomes = Counter(result.outcome for result in results)
        successes = [result for result in results if result.success]
        mean_time = statistics.fmean(r.simulation_time for r in results) if results else math.nan
        mean_success = (statistics.fmean(r.simulation_time for r in successes)
                        if successes else math.nan)
        steps = sum(result.steps for result in results)
        per_step = 1e3 * sum(r.controller_seconds for r in results) / steps if steps else math.nan
        faults = sum(r.fault_collisions for r in results) / total if total else math.nan
        collisions = sum(r.collisions for r in results) / total if total else math.nan
        print(f'| {scenario} | {total}/{sampled} | {percent(len(successes), total)} | '
              f'{faults:.2f} ({collisions:.2f}) | {percent(outcomes["stuck"], total)} | '
              f'{percent(outcomes["timeout"], total)} | '
              f'{percent(outcomes["collision_limit"], total)} | {mean_time:.1f} s '
              f'({mean_success:.1f} s) | {per_step:.2f} | {wall:.0f} |')


if __name__ == '__main__':
    sys.exit(main())
