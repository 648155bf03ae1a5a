#!/usr/bin/env python3
"""How often a child of a failing test fails, and with a new distinct fault, by how it is made.

The measurement the ``screened`` search (sessgan_evolver.screened_search) is built on. Not a
test; run it and read the figures::

    nice -n 5 python tests/benchmarks/bench_child_tests.py --scenario factory \\
        --controller nearness_diagram --fresh 200 --children 2 --seed 12

``--fresh`` fresh samples of the shipped generator are run (in process, one core); every
valid failure becomes a parent, and each parent gets ``--children`` children per way of
making one:

* ``new_sim``: the same test with a new simulator seed (agents, sensor noise);
* ``new_env``: the same map with a new environment seed (new start and goal);
* ``noise_S``: the generator noise mutated (``mutate_noise``, strength S), start and goal
  drawn again from the parent's environment seed on the changed map;
* ``keep_noise_S``, ``keep_fine_S``: the same mutation (all scales / the finest alone), the
  parent's start and goal kept and re-certified (``certify_route``);
* ``keep_local_S``: the finest scale mutated only around the parent's fault place.
* ``keep_two_finest_S``, ``keep_noise_S``: the two finest / all scales mutated everywhere, start
  and goal kept;
* ``keep_near_miss_0.8``: the finest scale mutated only around the parent's near miss (where
  its robot came closest to a wall before the fault, outside the fault's coarse cell), start
  and goal kept: does a change where the robot nearly failed make it fail there instead?
  (``--ways`` picks ways; default all).

Per way: the share of children that are valid tests, P(valid failure) and P(new distinct
fault) per child run (new: not seen before in the whole benchmark), and the share of run
children that showed their parent's fault again.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_core.token_map import tokens_to_occupancy  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeTrace  # noqa: E402
from sessgan_evolver.faults import (  # noqa: E402
    FaultKey,
    FaultRule,
    SituationArchive,
    first_fault_event,
)
from sessgan_evolver.in_process import InProcessEvaluator  # noqa: E402
from sessgan_evolver.map_operators import mutate_noise, mutate_noise_region  # noqa: E402
from sessgan_evolver.screening import certify_route, environment_of  # noqa: E402
from sessgan_evolver.search import EpisodeLog  # noqa: E402
from sessgan_evolver.search_methods import load_pyramid  # noqa: E402
from sessgan_gen.sampling import sample_token_maps_from_noise, seed_noise_maps  # noqa: E402
from sessgan_gen.track_cleanup import clean_generated_maps  # noqa: E402


class TracingLog(EpisodeLog):
    """An EpisodeLog that also keeps the last episode's trace and metrics."""

    def __call__(self, environment, seed, run, origin) -> None:
        super().__call__(environment, seed, run, origin)
        self.last_trace, self.last_metrics = run.trace, run.metrics


def near_miss_cell(environment: Environment, trace: EpisodeTrace, metrics, key: FaultKey,
                   rule: FaultRule) -> tuple[int, int] | None:
    """The coarse cell where the robot came closest to a wall before its fault, outside the
    fault's coarse cell (None: no such pose or no wall)."""
    rows, cols = np.nonzero(np.asarray(environment.occupancy) > 50)
    if not len(rows):
        return None
    wall_x = environment.origin[0] + (cols + 0.5) * environment.resolution
    wall_y = environment.origin[1] + (rows + 0.5) * environment.resolution
    fault_time = first_fault_event(metrics, trace).time
    best: tuple[float, int, int] | None = None
    for time_s, (x, y, _) in zip(trace.times, trace.poses):
        if time_s >= fault_time:
            break
        row, col = environment.cell_of(x, y)
        cell = (row // rule.coarse_cells, col // rule.coarse_cells)
        if cell == (key.row, key.col):
            continue
        distance = float(np.min(np.hypot(wall_x - x, wall_y - y)))
        if best is None or distance < best[0]:
            best = (distance, *cell)
    return None if best is None else best[1:]


def region_around(row: int, col: int, shape: tuple[int, int], rule: FaultRule
                  ) -> tuple[float, float, float, float]:
    """Coarse cell (row, col) and its context margin as (top, left, bottom, right) fractions
    of a map of ``shape`` cells (mutate_noise_region's region)."""
    height, width = shape
    side = rule.coarse_cells
    return (max(0.0, (row * side - rule.context_cells) / height),
            max(0.0, (col * side - rule.context_cells) / width),
            min(1.0, ((row + 1) * side + rule.context_cells) / height),
            min(1.0, ((col + 1) * side + rule.context_cells) / width))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='factory')
    parser.add_argument('--controller', default='')
    parser.add_argument('--fresh', type=int, default=200)
    parser.add_argument('--children', type=int, default=2)
    parser.add_argument('--seed', type=int, default=12)
    parser.add_argument('--ways', default='', help="comma-separated ways ('': all)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    spec = get_scenario(args.scenario)
    rule = FaultRule()
    rng = np.random.default_rng(args.seed)
    pyramid = load_pyramid(args.scenario, None)
    log = TracingLog(rule)

    def express(noise):
        return clean_generated_maps(sample_token_maps_from_noise(pyramid, [noise]),
                                    args.scenario)[0]

    def seed() -> int:
        return int(rng.integers(0, 2**32))

    started = time.perf_counter()
    archive: set[FaultKey] = set()
    situations = SituationArchive()
    parents = []
    with InProcessEvaluator(args.scenario, args.controller, simulate_invalid=False,
                            observer=log) as evaluator:
        def run(environment: Environment, sim_seed: int):
            evaluator.run_environment(environment, sim_seed)
            return log.records[-1]

        for _ in range(args.fresh):
            map_seed, sim_seed = seed(), seed()
            noise = seed_noise_maps(pyramid, map_seed)
            environment = make_environment(express(noise), args.scenario, 'fresh',
                                           seed=map_seed)
            record = run(environment, sim_seed)
            if record.fault is not None:
                archive.add(record.fault)
                situations.add(record.fault, environment.occupancy)
                near = near_miss_cell(environment, log.last_trace, log.last_metrics,
                                      record.fault, rule)
                parents.append((noise, environment, map_seed, sim_seed, record.fault, near))
        fresh_situations = len(situations)
        print(f'{args.fresh} fresh tests, {len(parents)} valid failures '
              f'({time.perf_counter() - started:.0f} s)', file=sys.stderr, flush=True)

        stats: dict[str, list[float]] = defaultdict(lambda: [0, 0, 0, 0, 0, 0, 0.0])
        for noise, environment, map_seed, sim_seed, key, near in parents:
            route = ((environment.start.x, environment.start.y, environment.start.yaw),
                     (environment.goal.x, environment.goal.y, environment.goal.yaw))
            shape = np.shape(environment.occupancy)
            region = region_around(key.row, key.col, shape, rule)
            last = (len(noise) - 1,)
            middle = (len(noise) - 2, len(noise) - 1)

            def kept(child_noise, child_sim: int | None = None):
                occupancy = tokens_to_occupancy(express(child_noise), spec)
                candidate = certify_route(occupancy, spec, *route)
                if not candidate.feasible:
                    return None
                return (environment_of(candidate, spec, 'child', map_seed),
                        sim_seed if child_sim is None else child_sim)

            def drawn(cells, environment_seed: int, child_sim: int):
                child = make_environment(cells, args.scenario, 'child', seed=environment_seed)
                return (child if child.feasible else None), child_sim

            ways: dict[str, Callable[[], tuple[Environment | None, int] | None]] = {
                'new_sim': lambda: (environment, seed()),
                'new_env': lambda: drawn(express(noise), seed(), seed()),
                'noise_0.1': lambda: drawn(express(mutate_noise(noise, rng, 0.1)), map_seed,
                                           sim_seed),
                'noise_0.3': lambda: drawn(express(mutate_noise(noise, rng, 0.3)), map_seed,
                                           sim_seed),
                'keep_noise_0.3': lambda: kept(mutate_noise(noise, rng, 0.3)),
                'keep_fine_0.15': lambda: kept(mutate_noise(noise, rng, 0.15, scales=last)),
                'keep_fine_0.3': lambda: kept(mutate_noise(noise, rng, 0.3, scales=last)),
                'keep_local_0.8': lambda: kept(mutate_noise_region(noise, rng, 0.8, region,
                                                                   last)),
                'keep_noise_0.5': lambda: kept(mutate_noise(noise, rng, 0.5)),
                'keep_two_finest_0.4': lambda: kept(mutate_noise(noise, rng, 0.4,
                                                                 scales=middle)),
                'keep_two_finest_0.7': lambda: kept(mutate_noise(noise, rng, 0.7,
                                                                 scales=middle)),
                'keep_two_finest_0.9': lambda: kept(mutate_noise(noise, rng, 0.9,
                                                                 scales=middle)),
                'keep_noise_0.7': lambda: kept(mutate_noise(noise, rng, 0.7)),
            }
            # A parent without a near miss (no wall, or none before the fault) has no such
            # child: counted as made, not as a valid test.
            near_region = None if near is None else region_around(*near, shape, rule)
            ways['keep_near_miss_0.8'] = lambda: None if near_region is None else kept(
                mutate_noise_region(noise, rng, 0.8, near_region, last))
            if args.ways:
                unknown = set(args.ways.split(',')) - set(ways)
                if unknown:
                    parser.error(f'unknown ways {sorted(unknown)}; known: {sorted(ways)}')
                ways = {name: make for name, make in ways.items()
                        if name in args.ways.split(',')}
            for name, make in ways.items():
                for _ in range(args.children):
                    made = make()
                    counts = stats[name]
                    counts[0] += 1
                    if made is None or made[0] is None:
                        continue
                    record = run(made[0], made[1])
                    counts[1] += 1
                    counts[2] += record.valid_failure
                    counts[6] += float(np.mean(np.asarray(made[0].occupancy)
                                               != np.asarray(environment.occupancy)))
                    if record.fault is not None:
                        counts[3] += record.fault not in archive
                        counts[4] += record.fault == key
                        counts[5] += situations.add(record.fault, made[0].occupancy)
                        archive.add(record.fault)
    print(f'\n{args.scenario}, {args.controller or spec.controller}: {args.fresh} fresh tests '
          f'(seed {args.seed}), {len(parents)} parents, {args.children} children each per '
          f'way, {time.perf_counter() - started:.0f} s\n')
    print('| way | children | valid tests | cells changed | P(valid failure) per run | '
          "P(new distinct fault) per run | P(new fault situation) per run | parent's fault "
          'again |')
    print('|---|---:|---:|---:|---:|---:|---:|---:|')
    print(f'| fresh sample | {args.fresh} | | | {len(parents) / args.fresh:.3f} | '
          f'{len(parents) / args.fresh:.3f} | {fresh_situations / args.fresh:.3f} | |')
    for name, (made, ran, failed, new, same, situation, changed) in stats.items():
        ran_or_one = max(ran, 1)
        print(f'| {name} | {made:.0f} | {ran / max(made, 1):.2f} | {changed / ran_or_one:.1%} | '
              f'{failed / ran_or_one:.3f} | {new / ran_or_one:.3f} | '
              f'{situation / ran_or_one:.3f} | {same / ran_or_one:.3f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
