#!/usr/bin/env python3
"""Benchmark: what the screened search's simulator-seed pick does to fresh tests.

Where the episodes have dummy agents, the screened search tries several simulator seeds per
kept candidate and runs the one whose agents come closest to the robot on its way
(``ScreenedSearch.pick_sim_seed``, ``screening.closest_encounter``). This runs fresh samples
of the shipped generator (certified as the search certifies them) with the robot under test,
once with the candidate's drawn seed and once with the pick among the first N of its seeds
for each ``--picks`` N, and prints per choice the share of maps that were valid failures and
that had a contact the robot drove into an agent (a fault) or an agent drove into the robot
(no fault), plus wall collisions. Same maps, same seeds for every choice. Usage::

    python tests/benchmarks/bench_agent_seed_pick.py [--controller nearness_diagram]
        [--maps 400] [--seed 21] [--picks 8,16]
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_core.token_map import tokens_to_occupancy  # noqa: E402
from sessgan_evolver.faults import is_valid_failure  # noqa: E402
from sessgan_evolver.in_process import InProcessEvaluator  # noqa: E402
from sessgan_evolver.screened_search import ScreenedSearch, Test  # noqa: E402
from sessgan_evolver.screening import certify_candidate, environment_of  # noqa: E402
from sessgan_gen.sampling import seed_noise_maps  # noqa: E402

COUNTS = {
    'valid failure': is_valid_failure,
    'robot drove into an agent': lambda m: int(m.get('robot_into_agent_collisions') or 0) > 0,
    'agent drove into the robot': lambda m: int(m.get('agent_into_robot_collisions') or 0) > 0,
    'wall collision': lambda m: int(m.get('static_collisions') or 0) > 0,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='factory')
    parser.add_argument('--controller', default='nearness_diagram')
    parser.add_argument('--maps', type=int, default=400, help='fresh maps with a route')
    parser.add_argument('--seed', type=int, default=21, help='seed of the maps and the search')
    parser.add_argument('--picks', default='8,16', help='seeds the pick chooses among')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    picks = [int(n) for n in args.picks.split(',') if n]
    search = ScreenedSearch(args.scenario, args.seed, controller=args.controller)
    if not int(search.episode_config.dummy_agents or 0):
        parser.error(f'the {args.scenario} episodes have no agents: there is no seed to pick')
    rng = np.random.default_rng(args.seed)

    def draw_seed() -> int:
        return int(rng.integers(0, 2**31))

    choices = ['drawn seed'] + [f'pick of {n}' for n in picks]
    counts: collections.Counter[tuple[str, str]] = collections.Counter()
    maps = 0
    with InProcessEvaluator(args.scenario, args.controller) as evaluator:
        while maps < args.maps:
            map_seed = draw_seed()
            noise = seed_noise_maps(search.pyramid, map_seed, search.size)
            cells = search.express([noise])[0]
            certified = certify_candidate(tokens_to_occupancy(cells, search.spec), search.spec,
                                          map_seed)
            if not certified.feasible:
                continue
            maps += 1
            test = Test(noise, cells, map_seed, map_seed, draw_seed(), 'fresh sample')
            test.environment = environment_of(certified, search.spec, 'bench', map_seed)
            options = [test.sim_seed] + [draw_seed() for _ in range(max(picks) - 1)]
            chosen = {'drawn seed': options[0]}
            for n in picks:
                test.seed_options = options[:n]
                search.pick_sim_seed(test, certified)
                chosen[f'pick of {n}'] = test.sim_seed
            runs: dict[int, dict] = {}
            for choice, seed in chosen.items():
                if seed not in runs:
                    runs[seed] = evaluator.run_environment(test.environment, seed).metrics
                for name, count in COUNTS.items():
                    counts[(choice, name)] += bool(count(runs[seed]))
            if maps % 50 == 0:
                print(f'{maps} maps: valid failures ' + ', '.join(
                    f'{choice} {counts[(choice, "valid failure")] / maps:.3f}'
                    for choice in choices), file=sys.stderr, flush=True)
    print(f'\n{args.scenario}, {args.controller}, {maps} fresh maps with a route (seed '
          f'{args.seed}): share of maps with\n')
    print('| seed | ' + ' | '.join(COUNTS) + ' |')
    print('|---|' + '---:|' * len(COUNTS))
    for choice in choices:
        print(f'| {choice} | ' + ' | '.join(f'{counts[(choice, name)] / maps:.3f}'
                                          for name in COUNTS) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
