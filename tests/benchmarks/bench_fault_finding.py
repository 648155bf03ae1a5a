#!/usr/bin/env python3
"""Fault-finding power of every method at equal budget, per controller: the issue's goals.

Runs ``compare`` (sessgan_evolver.comparison: every method, several search seeds, the same
in-process runner, certificate and fault rule) once per controller and prints, besides the
report's own table, the figures the goals are stated in:

* SESS-GAN's confirmed distinct faults per 1,000 episodes against random sampling's and the
  grid GA's (ratio of the means over seeds, and the seed-by-seed ratios);
* the fresh-seed valid-failure rate of each method's final generator (SESS-GAN's fittest
  member, the screened search's archive) against the shipped generator's, and its fresh
  maps' TPKL against the shipped generator's;
* every method's confirmed distinct faults against random sampling's (the ``screened``
  search's goal: 2.8x), its cheap work's share of its search wall time, and a stricter
  count, *fault situations*: confirmed faults of a run grouped when they have the same kind
  and coarse cell on maps that differ in fewer than 10 % of their cells (a local variant of
  the same failing map counts once; ``sessgan_evolver.faults.same_situation``, the rule the
  screened search's novelty uses).

``--budget`` takes a comma-separated list (one comparison per budget). Usage (CPU-heavy; run
with nice)::

    nice -n 10 python tests/benchmarks/bench_fault_finding.py --scenario factory \\
        --controllers nearness_diagram --seeds 0,1,2 --budget 360 --fresh 40
    nice -n 5 python tests/benchmarks/bench_fault_finding.py --scenario factory \\
        --controllers nearness_diagram --methods random,screened --seeds 100,101,102 \\
        --budget 100,300 --fresh 10
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_evolver.comparison import (  # noqa: E402
    CompareConfig,
    method_table,
    origin_table,
    run_comparison,
)
from sessgan_evolver.faults import SITUATION_CELLS, STRICT_SITUATION_CELLS  # noqa: E402
from sessgan_evolver.search_methods import METHODS  # noqa: E402


def mean_of(runs, method: str, key: str) -> float | None:
    values = [getattr(r.figures, key) for r in runs if r.figures.method == method
              and getattr(r.figures, key) is not None]
    return float(np.mean(values)) if values else None


def describe_ratio(runs, method: str, other: str, key: str) -> str:
    mine, theirs = mean_of(runs, method, key), mean_of(runs, other, key)
    if mine is None or theirs is None:
        return f'{method} vs {other}: no value'
    per_seed = []
    for run in runs:
        if run.figures.method != method:
            continue
        partner = next((r for r in runs if r.figures.method == other
                        and r.figures.search_seed == run.figures.search_seed), None)
        a, b = getattr(run.figures, key), getattr(partner.figures, key) if partner else None
        per_seed.append('n/a' if a is None or not b else f'{a / b:.2f}x')
    total = f'{mine / theirs:.2f}x' if theirs else 'inf'
    return (f'{method} vs {other}: {mine:.2f} vs {theirs:.2f} ({total}; per seed '
            f'{", ".join(per_seed)})')


SITUATION_FIGURES = (('situations_per_1000', SITUATION_CELLS),
                     ('strict_situations_per_1000', STRICT_SITUATION_CELLS))
"""RunFigures' fault situations by the project's rule and the stricter one, with the share of
cells below which two failing maps are one situation."""


def situation_ratios(runs, method: str) -> str:
    """A method's fault situations against random sampling's (ratio of the means over
    seeds), by the project's rule and the stricter one, so a gain that only holds at the
    project's threshold shows."""
    parts = []
    for key, share in SITUATION_FIGURES:
        mine, theirs = mean_of(runs, method, key), mean_of(runs, 'random', key)
        ratio = f'{mine / theirs:.2f}x' if mine is not None and theirs else 'n/a'
        parts.append(f'< {share:.0%} of cells: {ratio}')
    return f'{method} vs random, fault situations: ' + ', '.join(parts)


def describe_method(runs, method: str) -> str:
    """Per-seed figures of one method: confirmed faults, situations, first confirmed episode,
    cheap work share."""
    mine = sorted((r for r in runs if r.figures.method == method),
                  key=lambda r: r.figures.search_seed)
    confirmed = [r.figures.confirmed_per_1000 for r in mine]
    situations = [r.figures.situations_per_1000 for r in mine]
    strict = [r.figures.strict_situations_per_1000 for r in mine]
    first = [r.figures.first_confirmed_episode for r in mine]
    share = [100.0 * r.figures.cheap_wall / r.figures.search_wall for r in mine
             if r.figures.search_wall > 0]

    def spread(values) -> str:
        present = [float(v) for v in values if v is not None]
        if not present:
            return 'none'
        std = float(np.std(present, ddof=1)) if len(present) > 1 else 0.0
        return f'{np.mean(present):.1f} ± {std:.1f} ({", ".join(f"{v:.0f}" for v in present)})'
    return (f'{method}: confirmed distinct faults / 1,000 episodes {spread(confirmed)}; fault '
            f'situations / 1,000 episodes {spread(situations)} (maps differing in < '
            f'{STRICT_SITUATION_CELLS:.0%} of cells one situation: {spread(strict)}); episodes '
            f'to the first confirmed fault {spread(first)}; cheap work % of search wall '
            f'{spread(share)}')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='factory')
    parser.add_argument('--controllers', default='', help="comma-separated ('': scenario's)")
    parser.add_argument('--methods', default=','.join(METHODS))
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--budget', default='360', help='comma-separated budgets')
    parser.add_argument('--fresh', type=int, default=40)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--confirm-limit', type=int, default=0)
    parser.add_argument('--time-limit', type=float, default=0.0)
    parser.add_argument('--seed-schedule', default='per-generation')
    parser.add_argument('--population', type=int, default=12)
    parser.add_argument('--maps-per-member', type=int, default=3)
    parser.add_argument('--screening-effort', type=int, default=0,
                        help="the screened method's (0: its in-process default: 2 where the "
                        'episodes have agents, else 1)')
    parser.add_argument('--exploration', type=float, default=0.0,
                        help="the screened method's least share of fresh samples (0: its default)")
    parser.add_argument('--output', type=Path, default=Path('runs/bench-fault-finding'))
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    command = ' '.join(sys.argv[1:] if argv is None else argv)
    budgets = [int(b) for b in args.budget.split(',') if b]
    for controller in args.controllers.split(',') if args.controllers else ['']:
        for budget in budgets:
            run_one(args, controller, budget, command)
    return 0


def run_one(args: argparse.Namespace, controller: str, budget: int, command: str) -> None:
    config = CompareConfig(
        scenario=args.scenario, controller=controller,
        methods=tuple(m for m in args.methods.split(',') if m),
        search_seeds=tuple(int(s) for s in args.seeds.split(',') if s),
        budget=budget, fresh_episodes=args.fresh, repeats=args.repeats,
        confirm_limit=args.confirm_limit, time_limit=args.time_limit,
        seed_schedule=args.seed_schedule, population=args.population,
        maps_per_member=args.maps_per_member, screening_effort=args.screening_effort,
        exploration=args.exploration)
    effort = f'-effort{args.screening_effort}' if args.screening_effort else ''
    effort += f'-exploration{args.exploration:g}' if args.exploration else ''
    output = args.output / f'{args.scenario}-{controller or "default"}-{budget}{effort}'
    result = run_comparison(
        config, output, f'python tests/benchmarks/bench_fault_finding.py {command}',
        log=lambda message: print(f'[compare] {message}', file=sys.stderr, flush=True))
    print(f'\n## {args.scenario}, {controller or "default controller"}, {budget} episodes '
          f'({result.wall_time / 60:.1f} min; report {result.report_path})\n')
    print(method_table(config, result.runs))
    for other in ('random', 'grid_ga', 'latent'):
        if 'sessgan' in config.methods and other in config.methods:
            print(describe_ratio(result.runs, 'sessgan', other, 'confirmed_per_1000'))
    if 'random' in config.methods:
        for method in config.methods:
            if method not in ('random', 'sessgan'):
                print(describe_ratio(result.runs, method, 'random', 'confirmed_per_1000'))
    for method in config.methods:
        print(describe_method(result.runs, method))
    if 'random' in config.methods:
        for method in config.methods:
            if method != 'random':
                print(situation_ratios(result.runs, method))
    print('\nWhere the faults come from (episodes of each origin that first showed a confirmed '
          'distinct fault / a new fault situation):\n')
    print(origin_table(config, result.runs))
    shipped = result.fresh.get('pyramid:base')
    if shipped is not None:
        print(f'fresh seeds, shipped generator: failure rate {shipped.failure_rate}, TPKL '
              f'{shipped.tpkl:.3f}')
    for method in config.methods:
        runs = [r for r in result.runs if r.figures.method == method
                and r.source_key not in ('', 'pyramid:base')]
        if runs:
            print(f'fresh seeds, {method} final generators / archives: failure rates '
                  f'{[r.figures.fresh_failure_rate for r in runs]}, TPKL '
                  f'{[round(result.fresh[r.source_key].tpkl, 3) for r in runs]}')
    sys.stdout.flush()


if __name__ == '__main__':
    sys.exit(main())
