"""Benchmark of valid tests: how many generated maps are valid tests and how much room they give.

Not a test (pytest does not collect it); run it and read the figures::

    python tests/benchmarks/bench_valid_tests.py                  # 500 seeds per scenario
    python tests/benchmarks/bench_valid_tests.py --seeds 100 --scenario factory

For each scenario it samples maps from the shipped generator with fresh seeds (700000 on,
never used by training or tests) and reports the valid-test fraction (start and goal with
clearance >= robot radius + clearance_margin, a certified route with clearance >= radius +
route_margin, at least half the map's side apart), the start and goal clearances, the route's
bottleneck clearance and length, why maps were rejected, and the time per map.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

for package in ('sessgan_core', 'sessgan_gen'):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / package))

from sessgan_core.progress import ProgressPrinter  # noqa: E402
from sessgan_core.route_certificate import required_clearances  # noqa: E402
from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_gen.environment_sampler import EnvironmentSampler  # noqa: E402

FIRST_SEED = 700_000
BATCH = 50


def measure(scenario: str, seeds: int, progress: ProgressPrinter) -> dict:
    sampler = EnvironmentSampler()
    environments = []
    started = time.perf_counter()
    progress.start(f'{scenario} maps', seeds)
    for first in range(FIRST_SEED, FIRST_SEED + seeds, BATCH):
        batch = list(range(first, min(first + BATCH, FIRST_SEED + seeds)))
        environments += sampler.sample(batch, scenario=scenario)
        progress.update(len(environments))
    seconds = time.perf_counter() - started
    valid = [e for e in environments if e.feasible]
    ends = np.array([e.extra[key] for e in valid for key in ('start_clearance',
                                                              'goal_clearance')])
    bottleneck = np.array([e.route_min_clearance for e in valid])
    length = np.array([e.route_length for e in valid])
    return {
        'scenario': scenario, 'maps': len(environments), 'valid': len(valid),
        'needs': required_clearances(get_scenario(scenario)),
        'ends': ends, 'bottleneck': bottleneck, 'length': length,
        'rejections': Counter(e.extra['rejection'] for e in environments if not e.feasible),
        'ms_per_map': 1000 * seconds / len(environments),
    }


def row(result: dict) -> str:
    def spread(values: np.ndarray) -> str:
        if not len(values):
            return '-'
        return f'{values.min():.2f} / {np.median(values):.2f}'

    rejected = ', '.join(f'{reason} {100 * count / result["maps"]:.1f} %'
                         for reason, count in sorted(result['rejections'].items())) or 'none'
    place, route = result['needs']
    return (f'| {result["scenario"]} | {100 * result["valid"] / result["maps"]:.1f} % '
            f'({result["valid"]}/{result["maps"]}) | {place:.2f} / {route:.2f} | '
            f'{spread(result["ends"])} | {spread(result["bottleneck"])} | '
            f'{spread(result["length"])} | {rejected} | {result["ms_per_map"]:.0f} |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=500, help='maps per scenario [500]')
    parser.add_argument('--scenario', action='append', choices=('factory', 'drone',
                                                                'racetrack'),
                        help='scenario(s) to measure [all three]')
    args = parser.parse_args()
    progress = ProgressPrinter()
    results = [measure(name, args.seeds, progress)
               for name in args.scenario or ('factory', 'drone', 'racetrack')]
    print('| scenario | valid tests | needed clearance m (start, goal / route) | start and '
          'goal clearance m (min / median) | route bottleneck clearance m (min / median) | '
          'route length m (min / median) | rejected | ms per map (sample + certify) |')
    print('|---|---:|---:|---:|---:|---:|---|---:|')
    for result in results:
        print(row(result))


if __name__ == '__main__':
    main()
