#!/usr/bin/env python3
"""Benchmark: how much cheaper simulator settings would speed in-process screening, and how
often their episodes end otherwise than with the simulator's defaults.

The floor of an in-process episode is pybullet's ``stepSimulation`` alone,
``physics_rate / control_rate`` calls a tick (timed on the episode's own world): no
sensors, no controller, no Python. For fidelity, mutated copies of the scenario's example
map (``--maps``, each ``--mutations`` edits of sessgan_evolver.map_operators, start and goal
placed as for every test) run one episode each with the simulator's default settings (the
baseline, first on every map, same process) and with each ``--variant`` (cheaper settings:
a lower physics or control rate, fewer beams). Per variant it prints the CPU time a tick,
the sim/CPU factor and its ratio to the baseline's in the same run, and how many episodes
end with another outcome or another failure verdict than the baseline's (failed: not
goal_reached, or a fault collision). CPU time of this thread, as bench_in_process.py.
Usage::

    python tests/benchmarks/bench_screening_fidelity.py [--scenario factory]
        [--controller nearness_diagram] [--maps 20] [--variant physics_rate=20 ...]
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_core.scenarios import SCENARIOS, get_scenario  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeRunner  # noqa: E402
from sessgan_evolver.map_operators import mutate_token_map  # noqa: E402
from sessgan_sim.simulator_settings import SimulatorSettings  # noqa: E402


def failed(metrics: dict) -> bool:
    return metrics['outcome'] != 'goal_reached' or metrics['fault_collisions'] > 0


def environments(scenario: str, count: int, mutations: int, seed: int) -> list:
    """``count`` feasible environments of mutated copies of the scenario's example map."""
    spec = get_scenario(scenario)
    example = load_example_map(scenario).cells
    rng = np.random.default_rng(seed)
    found = []
    for attempt in range(50 * count):
        cells = example
        for _ in range(mutations):
            cells = mutate_token_map(cells, len(spec.tokens), rng, border=1)[0]
        environment = make_environment(cells, scenario, f'mutant{attempt}', seed=attempt)
        if environment.feasible:
            found.append(environment)
            if len(found) == count:
                break
    return found


def step_floor(runner: EpisodeRunner, calls: int = 2000) -> float:
    """CPU seconds of one stepSimulation call in the runner's world as its last episode left
    it."""
    episode = runner._episode  # noqa: SLF001 (the benchmark times the episode's own world)
    assert episode is not None
    client = episode._world.client  # noqa: SLF001
    started = time.thread_time()
    for _ in range(calls):
        p.stepSimulation(physicsClientId=client)
    return (time.thread_time() - started) / calls


def variant(text: str) -> tuple[str, SimulatorSettings]:
    """'name=value,...' of SimulatorSettings fields: the settings of one cheaper fidelity."""
    defaults = SimulatorSettings()
    changes = {}
    for item in text.split(','):
        name, _, value = item.partition('=')
        if not hasattr(defaults, name) or not value:
            raise argparse.ArgumentTypeError(f'not a simulator setting=value: {item!r}')
        changes[name] = type(getattr(defaults, name))(value)
    settings = dataclasses.replace(defaults, **changes)
    settings.validate()
    return text, settings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), default='factory')
    parser.add_argument('--controller', default='',
                        help="a controller of the registry ('' = the scenario's)")
    parser.add_argument('--maps', type=int, default=20)
    parser.add_argument('--mutations', type=int, default=3)
    parser.add_argument('--variant', type=variant, action='append',
                        help="cheaper settings to compare, e.g. 'physics_rate=20' or "
                             "'control_rate=10,physics_rate=50' (repeatable; default: "
                             'physics at 20 and 50 Hz, control at 10 Hz)')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    variants = [('default', SimulatorSettings()), *(args.variant or [
        variant('physics_rate=20'), variant('physics_rate=50'),
        variant('control_rate=10,physics_rate=50')])]
    runners = {name: EpisodeRunner(args.scenario, args.controller, settings=settings,
                                   clock=time.thread_time).open()
               for name, settings in variants}
    cpu: collections.Counter[str] = collections.Counter()
    sim: collections.Counter[str] = collections.Counter()
    ticks: collections.Counter[str] = collections.Counter()
    other_outcome: collections.Counter[str] = collections.Counter()
    other_verdict: collections.Counter[str] = collections.Counter()
    failures: collections.Counter[str] = collections.Counter()
    maps = environments(args.scenario, args.maps, args.mutations, args.seed)
    for index, environment in enumerate(maps):
        # The baseline first, then each variant: every pair runs in the same conditions.
        runs = {name: runner.run(environment, index + 1) for name, runner in runners.items()}
        reference = runs['default'].metrics
        for name, run in runs.items():
            cpu[name] += run.wall_time
            sim[name] += run.metrics['simulation_time']
            ticks[name] += run.metrics['ticks']
            failures[name] += failed(run.metrics)
            other_outcome[name] += run.metrics['outcome'] != reference['outcome']
            other_verdict[name] += failed(run.metrics) != failed(reference)
    floor = {name: step_floor(runner) for name, runner in runners.items()}
    for runner in runners.values():
        runner.close()
    print(f"{args.scenario} / {runners['default'].controller_name}: {len(maps)} maps, "
          f'{args.mutations} mutations each; load average {os.getloadavg()[0]:.1f}')
    print('| settings | CPU ms / tick | sim / CPU time | speed vs default | failures | '
          'other outcome | other verdict | stepSimulation alone a tick |')
    print('|---|---:|---:|---:|---:|---:|---:|---:|')
    base = sim['default'] / cpu['default']
    for name, settings in variants:
        steps = max(1, round(settings.physics_rate / settings.control_rate))
        per_tick = floor[name] * steps
        speed = sim[name] / cpu[name]
        print(f'| {name} | {cpu[name] / ticks[name] * 1e3:.3f} | x{speed:.0f} '
              f'| {speed / base:.2f} | {failures[name]}/{len(maps)} '
              f'| {other_outcome[name]} | {other_verdict[name]} '
              f'| {per_tick * 1e3:.3f} ms (x{1 / settings.control_rate / per_tick:.0f}) |')


if __name__ == '__main__':
    main()
