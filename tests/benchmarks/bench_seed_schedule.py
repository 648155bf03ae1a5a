#!/usr/bin/env python3
"""Which seed schedule generalises best to fresh seeds: fixed, per-generation or rotating?

For each schedule and search seed, a SESS-GAN campaign runs in process (the same episode
runner as ``compare``) with the given budget; then, on ONE plan of fresh (map, simulator)
seed pairs disjoint from every seed of every campaign (sessgan_evolver.fresh_seed):

* the fittest member of the campaign's last generation,
* its whole last population (map i from member i mod n, so N maps cost N episodes),
* the shipped generator (once; the common reference)

are run on the same pairs. Printed per run and per schedule (mean ± sample std over seeds):
the valid-failure rate and the mean risk on fresh seeds, their ratio to the shipped
generator's, the TPKL of the fresh maps relative to the shipped generator's (the realism
cost), and the in-search risk of generation 0 and of the last generation (what the search
saw). Everything goes to <output>/ as CSV and markdown as well.

Usage (CPU-heavy; run with nice)::

    nice -n 10 python tests/benchmarks/bench_seed_schedule.py --scenario factory \\
        --seeds 0,1,2 --generations 8 --population 12 --maps-per-member 3 --fresh 60
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'sessgan_evolver',
                'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_evolver.campaign import SEED_SCHEDULES, Campaign, CampaignConfig  # noqa: E402
from sessgan_evolver.fresh_seed import (  # noqa: E402
    PopulationSource,
    PyramidSource,
    campaign_sources,
    evaluate_source,
    fresh_seed_plan,
    used_seeds,
    write_csv,
)
from sessgan_evolver.in_process import InProcessEvaluator  # noqa: E402
from sessgan_evolver.run_store import RunStore  # noqa: E402


def mean_std(values: list[float | None]) -> str:
    present = [v for v in values if v is not None and math.isfinite(v)]
    if not present:
        return 'none'
    text = f'{np.mean(present):.3f}'
    if len(present) > 1:
        text += f' ± {np.std(present, ddof=1):.3f}'
    if len(present) < len(values):
        text += f' ({len(present)}/{len(values)})'
    return text


def ratio(value: float | None, reference: float | None) -> float | None:
    if value is None or reference is None or reference <= 0:
        return None
    return value / reference


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='factory')
    parser.add_argument('--controller', default='')
    parser.add_argument('--schedules', default=','.join(SEED_SCHEDULES))
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--generations', type=int, default=8)
    parser.add_argument('--population', type=int, default=12)
    parser.add_argument('--maps-per-member', type=int, default=3)
    parser.add_argument('--seed-pool', type=int, default=0,
                        help='rotating: pool size (0: 4 x maps per member)')
    parser.add_argument('--time-limit', type=float, default=0.0)
    parser.add_argument('--fresh', type=int, default=60, help='fresh seed pairs')
    parser.add_argument('--evaluation-seed', type=int, default=2000)
    parser.add_argument('--output', type=Path, default=Path('runs/bench-seed-schedule'))
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    schedules = [s for s in args.schedules.split(',') if s]
    seeds = [int(s) for s in args.seeds.split(',') if s]
    output = args.output
    started = time.perf_counter()
    run_dirs: dict[tuple[str, int], Path] = {}
    rows = []
    for schedule in schedules:
        for seed in seeds:
            config = CampaignConfig(
                scenario=args.scenario, generations=args.generations,
                population=args.population, maps_per_member=args.maps_per_member, seed=seed,
                controller=args.controller, time_limit=args.time_limit,
                seed_schedule=schedule, seed_pool=args.seed_pool, record_failures=False)
            name = f'{schedule}-seed{seed}'
            campaign = Campaign(config, name, output / 'runs', output / 'bags',
                                log=lambda message: print(f'[{name}] {message}',
                                                          file=sys.stderr))
            store = campaign.store
            if len(store.read_rows('generation')) == args.generations:
                print(f'[{name}] reusing the finished run', file=sys.stderr)
            else:  # a new run, or one killed half-way: resume it
                with InProcessEvaluator(args.scenario, args.controller,
                                        args.time_limit) as evaluator:
                    campaign.run(evaluator, resume=store.latest_checkpoint() is not None)
            run_dirs[(schedule, seed)] = campaign.store.run_dir
    plan = fresh_seed_plan(args.evaluation_seed, args.fresh, *used_seeds(run_dirs.values()))
    print(f'{len(plan.pairs)} fresh seed pairs, {plan.skipped} skipped; excluded '
          f'{plan.excluded_map_seeds} map and {plan.excluded_sim_seeds} simulator seeds')
    with InProcessEvaluator(args.scenario, args.controller, args.time_limit,
                            simulate_invalid=False) as evaluator:
        shipped = evaluate_source(PyramidSource('shipped', args.scenario), plan,
                                  evaluator).summary
        for (schedule, seed), run_dir in run_dirs.items():
            generations = RunStore(run_dir.parent, run_dir.name).read_rows('generation')
            best = evaluate_source(campaign_sources(run_dir, 'best')[0], plan,
                                   evaluator).summary
            final = evaluate_source(PopulationSource('final population',
                                                     campaign_sources(run_dir, 'final')),
                                    plan, evaluator).summary
            rows.append({
                'schedule': schedule, 'seed': seed,
                'search_risk_first': generations[0]['mean_risk_score'],
                'search_risk_last': generations[-1]['mean_risk_score'],
                'best_failure_rate': best.failure_rate, 'best_risk': best.mean_risk,
                'best_failure_ratio': ratio(best.failure_rate, shipped.failure_rate),
                'best_risk_ratio': ratio(best.mean_risk, shipped.mean_risk),
                'best_tpkl_ratio': ratio(best.tpkl, shipped.tpkl),
                'best_valid_fraction': best.valid_fraction,
                'final_failure_rate': final.failure_rate, 'final_risk': final.mean_risk,
                'final_failure_ratio': ratio(final.failure_rate, shipped.failure_rate),
                'final_risk_ratio': ratio(final.mean_risk, shipped.mean_risk),
                'final_tpkl_ratio': ratio(final.tpkl, shipped.tpkl),
                'shipped_failure_rate': shipped.failure_rate, 'shipped_risk': shipped.mean_risk,
                'shipped_tpkl': shipped.tpkl})
            print(f'{schedule:>15} seed {seed}: best member fresh failure rate '
                  f'{best.failure_rate} (shipped {shipped.failure_rate}), risk '
                  f'{best.mean_risk} (shipped {shipped.mean_risk}); final population '
                  f'{final.failure_rate}, risk {final.mean_risk}', flush=True)
    write_csv(output / 'seed_schedule.csv', rows)
    columns = [('best_failure_rate', 'fresh failure rate, best member'),
               ('best_failure_ratio', '  / shipped'),
               ('best_risk', 'fresh mean risk, best member'),
               ('best_risk_ratio', '  / shipped'),
               ('best_tpkl_ratio', 'fresh TPKL / shipped, best member'),
               ('final_failure_rate', 'fresh failure rate, final population'),
               ('final_risk', 'fresh mean risk, final population'),
               ('final_risk_ratio', '  / shipped'),
               ('final_tpkl_ratio', 'fresh TPKL / shipped, final population'),
               ('search_risk_first', 'search risk, generation 0'),
               ('search_risk_last', 'search risk, last generation')]
    lines = [f'Seed schedules on {args.scenario} ({args.controller or "default controller"}): '
             f'{args.generations} generations x {args.population} x {args.maps_per_member}, '
             f'seeds {seeds}; {len(plan.pairs)} fresh pairs; shipped generator: failure '
             f'rate {shipped.failure_rate}, risk {shipped.mean_risk}, TPKL {shipped.tpkl:.3f}; '
             f'{(time.perf_counter() - started) / 60:.1f} min', '',
             '| | ' + ' | '.join(schedules) + ' |', '|---|' + '---:|' * len(schedules)]
    for key, label in columns:
        cells = [mean_std([row[key] for row in rows if row['schedule'] == schedule])
                 for schedule in schedules]
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    text = '\n'.join(lines)
    (output / 'seed_schedule.md').write_text(
        f'Command: `python tests/benchmarks/bench_seed_schedule.py '
        f'{" ".join(sys.argv[1:] if argv is None else argv)}`\n\n{text}\n')
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
