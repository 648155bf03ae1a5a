#!/usr/bin/env python3
"""One picture of fault-finding power from ``bench_fault_finding.py`` outputs.

Reads the ``runs.csv`` of every report folder given (``<scenario>-<controller>-<budget>``,
the benchmark's naming, an ``-effortN`` suffix allowed) and draws, per robot under test, the
confirmed distinct faults per 1,000 episodes of each method at each budget: the mean over
search seeds as a bar, each seed as a dot, and each method's ratio to random sampling's mean
above its bar; with ``--goal G`` a dashed line at G times random's mean. A (robot, budget,
method, seed) given again in a later folder replaces the earlier one (said on the console):
pass newer runs last, e.g. a method re-measured after a change beside the baseline measured
before it. Usage::

    python tests/benchmarks/plot_fault_finding.py runs/bench-fault-finding/*/ \\
        --png fault_finding_matrix.png
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

METHOD_COLOURS = {'random': '#9e9e9e', 'screened': '#1f77b4', 'latent': '#ff7f0e',
                  'sessgan': '#2ca02c', 'grid_ga': '#8c564b', 'cellular_automaton': '#e377c2'}

COLUMNS = ('method', 'search_seed', 'confirmed_per_1000')
"""The columns of runs.csv read."""

Key = tuple[str, int, str]
"""(robot as 'scenario, controller', budget, method)"""


def read_runs(folders: list[Path]) -> dict[Key, dict[int, float]]:
    """Confirmed distinct faults per 1,000 episodes by (robot, budget, method) and seed."""
    values: dict[Key, dict[int, float]] = defaultdict(dict)
    for folder in folders:
        table = folder / 'runs.csv'
        if not table.is_file():
            raise SystemExit(f'{folder}: no runs.csv (not a bench_fault_finding report folder)')
        parts = folder.resolve().name.split('-')
        if len(parts) < 3 or not parts[2].isdigit():
            raise SystemExit(f'{folder}: expected a folder named <scenario>-<controller>-<budget>'
                             f'[-effortN], got {folder.name!r}')
        robot, budget = f'{parts[0]}, {parts[1]}', int(parts[2])
        with open(table, newline='') as stream:
            reader = csv.DictReader(stream)
            missing = set(COLUMNS) - set(reader.fieldnames or ())
            if missing:
                raise SystemExit(f'{table}: no column {", ".join(sorted(missing))}')
            for row in reader:
                key, seed = (robot, budget, row['method']), int(row['search_seed'])
                if seed in values[key]:
                    print(f'{folder}: {row["method"]} seed {seed} of {robot} at {budget} '
                          "episodes replaces the earlier folder's")
                values[key][seed] = float(row['confirmed_per_1000'])
    if not values:
        raise SystemExit('no runs in the folders given')
    return values


def plot(values: dict[Key, dict[int, float]], png: Path, columns: int, goal: float) -> None:
    robots = sorted({robot for robot, _, _ in values})
    methods = sorted({method for _, _, method in values},
                     key=lambda m: (m != 'random', m != 'screened', m))
    rows = -(-len(robots) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows),
                                squeeze=False)
    width = 0.8 / len(methods)
    for ax, robot in zip(axes.flat, robots):
        budgets = sorted({budget for r, budget, _ in values if r == robot})
        for b, budget in enumerate(budgets):
            baseline = values.get((robot, budget, 'random'), {})
            base_mean = np.mean(list(baseline.values())) if baseline else None
            if goal and base_mean:
                ax.hlines(goal * base_mean, b - 0.45, b + 0.45, colors='k', linestyles='--',
                          linewidth=1, label=f'{goal:g}× random')
            for m, method in enumerate(methods):
                seeds = values.get((robot, budget, method))
                if not seeds:
                    continue
                x = b + (m - (len(methods) - 1) / 2) * width
                points = np.array(list(seeds.values()))
                mean = float(points.mean())
                # Every bar labelled: a method run at one budget only is in the legend too
                # (the figure's legend keeps one handle a label).
                ax.bar(x, mean, width * 0.9, color=METHOD_COLOURS.get(method, '#17becf'),
                       label=method)
                ax.plot(np.full(len(points), x), points, 'k.', ms=4)
                if method != 'random' and base_mean:
                    ax.annotate(f'{mean / base_mean:.1f}×', (x, max(mean, points.max())),
                                ha='center', va='bottom', fontsize=8,
                                xytext=(0, 2), textcoords='offset points')
                elif method != 'random' and baseline:
                    ax.annotate('random: 0', (x, max(mean, points.max())), ha='center',
                                va='bottom', fontsize=7, xytext=(0, 2),
                                textcoords='offset points')
        ax.set_xticks(range(len(budgets)), [f'{budget} episodes' for budget in budgets])
        ax.set_title(robot, fontsize=10)
        ax.set_ylabel('confirmed faults / 1,000 episodes', fontsize=8)
        ax.margins(y=0.15)
    for ax in list(axes.flat)[len(robots):]:
        ax.axis('off')
    legend: dict[str, Any] = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(label, handle)
    figure.legend(handles=list(legend.values()), labels=list(legend), loc='lower right',
                  fontsize=9)
    figure.suptitle('Confirmed distinct faults per 1,000 episodes of the robot under test\n'
                    '(bar: mean over search seeds, dots: seeds; × random sampling)',
                    fontsize=10)
    figure.tight_layout(rect=(0, 0, 1, 0.93))
    figure.savefig(png, dpi=90)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('folders', nargs='+', type=Path,
                        help='bench_fault_finding report folders (each with a runs.csv)')
    parser.add_argument('--png', type=Path, default=Path('fault_finding_matrix.png'))
    parser.add_argument('--columns', type=int, default=4)
    parser.add_argument('--goal', type=float, default=0.0,
                        help="draw this multiple of random sampling's mean (0: none)")
    args = parser.parse_args(argv)
    if args.columns < 1:
        parser.error(f'--columns must be >= 1, got {args.columns}')
    if args.goal < 0:
        parser.error(f'--goal must not be negative, got {args.goal}')
    values = read_runs(args.folders)
    plot(values, args.png, args.columns, args.goal)
    for (robot, budget, method), seeds in sorted(values.items()):
        points = list(seeds.values())
        print(f'{robot}, {budget} episodes, {method}: {np.mean(points):.1f} ± '
              f'{np.std(points, ddof=1) if len(points) > 1 else 0.0:.1f} '
              f'(seeds {", ".join(str(s) for s in sorted(seeds))})')
    print(f'wrote {args.png}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
