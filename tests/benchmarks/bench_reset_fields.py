#!/usr/bin/env python3
"""Benchmark: the grid fields an episode's reset computes, and the whole reset, per scenario.

Every in-process episode starts with ``Episode.reset``, which builds the map's clearance field
(sessgan_core.route_certificate.map_clearance) and each leg's progress field (a diagonal
distance field, sessgan_sim.progress.progress_field) before the world. Per scenario (its
example map, reference start and goal) this prints the CPU time of each, and of a whole reset.

``--baseline-tree DIR`` (a checkout of another commit) loads that tree's
``route_certificate.py`` and ``grid_search.py`` and alternates, ``--repeats`` times, a reset
with this tree's fields and one with the baseline's in the same process (same world, same
caches), checking that both give the same fields bit for bit. CPU time of this thread.
Usage::

    python tests/benchmarks/bench_reset_fields.py [--repeats 20] [--baseline-tree DIR]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

import numpy as np  # noqa: E402

import sessgan_core.route_certificate as route_certificate  # noqa: E402
import sessgan_sim.progress as progress  # noqa: E402
from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.route_certificate import (  # noqa: E402
    CertificateGrid,
    map_clearance,
    required_clearances,
)
from sessgan_core.scenarios import SCENARIOS, Scenario, get_scenario  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeRunner  # noqa: E402


def load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        sys.exit(f'cannot load {path}')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cpu_ms(call: Callable[[], object], repeats: int) -> float:
    """Median CPU ms of ``call``."""
    times = []
    for _ in range(repeats):
        started = time.thread_time()
        call()
        times.append(time.thread_time() - started)
    return statistics.median(times) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repeats', type=int, default=20)
    parser.add_argument('--baseline-tree', type=Path)
    args = parser.parse_args()
    ours = (route_certificate.clearance_field, progress.distance_field)
    theirs = None
    if args.baseline_tree is not None:
        core = args.baseline_tree / 'sessgan_core' / 'sessgan_core'
        if not core.is_dir():
            parser.error(f'--baseline-tree {args.baseline_tree}: no sessgan_core package')
        theirs = (load(core / 'route_certificate.py', 'baseline_route_certificate')
                  .clearance_field,
                  load(core / 'grid_search.py', 'baseline_grid_search').distance_field)

    def use(fields: tuple[Callable, Callable]) -> None:
        route_certificate.clearance_field, progress.distance_field = fields

    print(f'load average {os.getloadavg()[0]:.1f}; CPU ms, medians of {args.repeats}')
    print('| scenario | map | clearance field | progress field | reset |'
          + (' reset, baseline fields | reset vs baseline |' if theirs else ''))
    print('|---|---|---:|---:|---:|' + ('---:|---:|' if theirs else ''))
    for scenario in sorted(SCENARIOS):
        spec = get_scenario(scenario)
        environment = make_environment(load_example_map(scenario).cells, scenario, 'reference')
        grid = map_clearance(environment.occupancy, environment.resolution,
                             environment.origin, spec)
        need = required_clearances(spec)[1]
        leg = (environment.start, environment.goal, bool(environment.feasible), spec.robot_radius,
               need)
        clearance = cpu_ms(lambda: map_clearance(environment.occupancy, environment.resolution,
                                                 environment.origin, spec), args.repeats)
        fields = cpu_ms(lambda: progress.progress_field(grid, *leg), args.repeats)
        with EpisodeRunner(scenario, clock=time.thread_time) as runner:
            episode = runner._episode  # noqa: SLF001 (the benchmark times its reset)
            assert episode is not None
            config = runner.episode_config(1, environment)
            resets: dict[bool, list[float]] = {True: [], False: []}
            for repeat in range(args.repeats):
                for mine in ((True, False) if repeat % 2 == 0 else (False, True)):
                    if not mine and theirs is None:
                        continue
                    use(ours if mine or theirs is None else theirs)
                    episode.reset(environment, config)
                    resets[mine].append(episode.profile.reset)
            use(ours)
        row = (f'| {scenario} | {environment.occupancy.shape[0]}x'
               f'{environment.occupancy.shape[1]} | {clearance:.2f} | {fields:.2f} | '
               f'{statistics.median(resets[True]) * 1e3:.2f} |')
        if theirs is not None:
            same = (np.array_equal(theirs[0](*_clearance_args(environment, spec)).clearance,
                                   grid.clearance)
                    and np.array_equal(_progress_steps(theirs, grid, leg),
                                       _progress_steps(ours, grid, leg)))
            if not same:
                sys.exit(f"{scenario}: the baseline's fields differ from this tree's")
            base = statistics.median(resets[False])
            row += (f' {base * 1e3:.2f} | {statistics.median(resets[True]) / base:.2f} |')
        print(row, flush=True)


def _clearance_args(environment: Environment, spec: Scenario) -> tuple:
    """map_clearance's call of clearance_field."""
    allowed = sorted({spec.occupancy[token] for token in spec.traversable})
    blocked = ~np.isin(np.asarray(environment.occupancy), allowed)
    return (blocked, environment.resolution, route_certificate.certificate_subdivision(spec),
            required_clearances(spec)[0] + 1.0, environment.origin)


def _progress_steps(fields: tuple[Callable, Callable], grid: CertificateGrid,
                    leg: tuple) -> np.ndarray:
    saved = progress.distance_field
    progress.distance_field = fields[1]
    try:
        return progress.progress_field(grid, *leg).steps
    finally:
        progress.distance_field = saved


if __name__ == '__main__':
    main()
