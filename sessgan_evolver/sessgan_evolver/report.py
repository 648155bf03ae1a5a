"""The campaign report: plots and tables from a run directory (matplotlib, Agg backend).

``write_report(run_dir, ...)`` writes ``<run_dir>/report/``::

    report.md                 ties everything together (relative links); leads with the
                              valid failures and distinct faults found (fault_tally)
    faults_found.png          valid failures and distinct faults so far against episodes,
                              fault risk and the paper's risk per generation
    generation_metrics.png    mean and best simulation time, proximity time, collisions and
                              risk score per generation (the paper's Fig. 10)
    search_progress.png       fitness, feasible fraction and TPKL per generation
    maps.png                  sample maps at generations 0, 25 %, 50 %, 100 % (Fig. 9),
                              when the caller passes maps
    tpkl.png, uniqueness.png  TPKL and uniqueness of the last population, when passed

Per-generation values come from the 'generation' rows of metrics.jsonl
(``fitness.generation_summary``): ``mean_<metric>`` pooled over the generation's feasible
episodes, ``best_<metric>`` of its fittest member.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402
from matplotlib.colors import BoundaryNorm, ListedColormap  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from sessgan_evolver.errors import ReportError, RunStoreError  # noqa: E402
from sessgan_evolver.fault_tally import (  # noqa: E402
    UNPLACED,
    FaultTally,
    OriginFigures,
    origin_family,
    origin_rows,
)
from sessgan_evolver.run_store import RunStore  # noqa: E402

FIGURE_DPI = 120

GENERATION_PANELS = (
    ('simulation_time', 'Simulation time (s)'),
    ('proximity_time', 'Proximity time (s)'),
    ('collisions', 'Collisions'),
    ('risk_score', 'Risk score'),
)
"""(metric, axis label) of the four Fig. 10 panels."""

OCCUPANCY_COLOURS = {0: '#ffffff', 50: '#9e9e9e', 100: '#000000'}
"""Colours of OccupancyGrid values: free white, low obstacle grey, wall black."""

TOKEN_COLOURS = ('#f2efe6', '#2b2b2b', '#c0392b', '#2e86c1', '#27ae60', '#8e44ad', '#f39c12')
"""Colours of token ids 0, 1, 2, ... when maps are token grids."""


def report_generations(last_generation: int) -> list[int]:
    """The generations Fig. 9 shows: 0, 25 %, 50 % and 100 % of ``last_generation``
    (rounded, duplicates removed)."""
    if last_generation < 0:
        raise ReportError(f'last generation must be >= 0, got {last_generation}')
    picks = [0, round(0.25 * last_generation), round(0.5 * last_generation), last_generation]
    return sorted({int(p) for p in picks})


def plot_generation_metrics(generation_rows: Sequence[Mapping[str, Any]],
                            path: str | Path) -> Path:
    """Fig. 10: four panels (simulation time, proximity time, collisions, risk score), each
    with the generation mean and the fittest member's value per generation."""
    rows = _sorted_rows(generation_rows)
    generations = [row['generation'] for row in rows]
    figure, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True)
    for axis, (metric, label) in zip(axes.flat, GENERATION_PANELS):
        axis.plot(generations, _column(rows, f'mean_{metric}'), marker='o', markersize=3,
                  label='population mean')
        axis.plot(generations, _column(rows, f'best_{metric}'), marker='.', markersize=3,
                  linestyle='--', alpha=0.8, label='fittest member')
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    for axis in axes[1]:
        axis.set_xlabel('Generation')
    axes[0][0].legend(loc='best', fontsize='small')
    figure.suptitle('Risk metrics per generation (feasible maps)')
    return _save(figure, path)


def plot_search_progress(generation_rows: Sequence[Mapping[str, Any]],
                         path: str | Path) -> Path:
    """Three panels: mean and best fitness, feasible fraction, mean TPKL (with the
    generation-0 reference and 1.5x that reference)."""
    rows = _sorted_rows(generation_rows)
    generations = [row['generation'] for row in rows]
    figure, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    axes[0].plot(generations, _column(rows, 'mean_fitness'), marker='o', markersize=3,
                 label='mean')
    axes[0].plot(generations, _column(rows, 'best_fitness'), marker='.', markersize=3,
                 linestyle='--', label='best')
    axes[0].set_ylabel('Fitness')
    axes[0].legend(fontsize='small')
    axes[1].plot(generations, _column(rows, 'feasible_fraction'), marker='o', markersize=3)
    axes[1].axhline(0.9, color='grey', linestyle=':', linewidth=1)
    axes[1].set_ylim(0.0, 1.05)
    axes[1].set_ylabel('Feasible fraction')
    axes[2].plot(generations, _column(rows, 'mean_tpkl'), marker='o', markersize=3,
                 label='mean TPKL')
    reference = next((row.get('tpkl_reference') for row in rows
                      if row.get('tpkl_reference') is not None), None)
    if reference is not None:
        axes[2].axhline(reference, color='grey', linestyle=':', linewidth=1,
                        label='generation 0')
        axes[2].axhline(1.5 * reference, color='red', linestyle=':', linewidth=1,
                        label='1.5 x generation 0')
    axes[2].set_ylabel('TPKL (nats)')
    axes[2].legend(fontsize='small')
    for axis in axes:
        axis.set_xlabel('Generation')
        axis.grid(alpha=0.3)
    return _save(figure, path)


def plot_maps(maps_by_generation: Mapping[int, Sequence[np.ndarray]], path: str | Path,
              token_names: Sequence[str] | None = None) -> Path:
    """Fig. 9: one row per generation, one column per sample map.

    Maps are OccupancyGrid grids (values 0/50/100, row 0 = lowest y) or token grids (ids
    0..n-1, ``token_names`` label them); both are drawn with row 0 at the bottom.
    """
    if not maps_by_generation:
        raise ReportError('no maps to plot')
    generations = sorted(maps_by_generation)
    columns = max(len(maps_by_generation[g]) for g in generations)
    if columns == 0:
        raise ReportError('every generation has an empty list of maps')
    all_values = np.unique(np.concatenate([np.unique(np.asarray(m))
                                           for g in generations
                                           for m in maps_by_generation[g]]))
    colormap, norm, legend = _map_colours(all_values, token_names)
    figure, axes = plt.subplots(len(generations), columns,
                                figsize=(2.2 * columns, 2.3 * len(generations)),
                                squeeze=False)
    for row, generation in enumerate(generations):
        for column in range(columns):
            axis = axes[row][column]
            axis.set_xticks([])
            axis.set_yticks([])
            maps = maps_by_generation[generation]
            if column < len(maps):
                axis.imshow(np.asarray(maps[column]), cmap=colormap, norm=norm,
                            origin='lower', interpolation='nearest')
            else:
                axis.set_axis_off()
            if column == 0:
                axis.set_ylabel(f'generation {generation}')
    if legend:
        handles = [plt.Rectangle((0, 0), 1, 1, facecolor=colour, edgecolor='black')
                   for _, colour in legend]
        figure.legend(handles, [name for name, _ in legend], loc='lower center',
                      ncol=len(legend), fontsize='small')
    figure.suptitle('Sample maps per generation')
    # Leave room below the axes for the figure legend.
    return _save(figure, path, bottom=0.6 / figure.get_figheight() if legend else 0.0)


def plot_table(table: Mapping[str, Mapping[str, float]], path: str | Path, title: str,
               value_format: str = '{:.3f}') -> Path:
    """A table (row label -> column label -> value) as an annotated heat map."""
    row_labels, column_labels, values = _table_arrays(table)
    figure, axis = plt.subplots(figsize=(1.6 + 1.2 * len(column_labels),
                                         1.2 + 0.4 * len(row_labels)))
    image = axis.imshow(values, cmap='viridis', aspect='auto')
    axis.set_xticks(range(len(column_labels)), column_labels)
    axis.set_yticks(range(len(row_labels)), row_labels)
    finite = values[np.isfinite(values)]
    middle = float(np.mean([finite.min(), finite.max()])) if finite.size else 0.0
    for i in range(len(row_labels)):
        for j in range(len(column_labels)):
            value = values[i, j]
            text = '' if math.isnan(value) else value_format.format(value)
            axis.text(j, i, text, ha='center', va='center', fontsize='small',
                      color='black' if value > middle else 'white')
    figure.colorbar(image, ax=axis)
    axis.set_title(title)
    return _save(figure, path)


def markdown_table(table: Mapping[str, Mapping[str, float]], corner: str = '',
                   value_format: str = '{:.3f}') -> str:
    """A table (row label -> column label -> value) as GitHub markdown."""
    row_labels, column_labels, values = _table_arrays(table)
    lines = [f'| {corner} | ' + ' | '.join(column_labels) + ' |',
             '|---|' + '---:|' * len(column_labels)]
    for label, row in zip(row_labels, values):
        cells = ['' if math.isnan(v) else value_format.format(v) for v in row]
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def write_report(run_dir: str | Path,
                 maps_by_generation: Mapping[int, Sequence[np.ndarray]] | None = None,
                 tpkl_table: Mapping[str, Mapping[str, float]] | None = None,
                 uniqueness_table: Mapping[str, Mapping[str, float]] | None = None,
                 title: str | None = None,
                 token_names: Sequence[str] | None = None,
                 notes: Sequence[str] = ()) -> Path:
    """Write ``<run_dir>/report/`` (module docstring) and return the path of report.md.

    ``maps_by_generation``: generation -> sample maps (see ``report_generations``).
    ``tpkl_table``: row (e.g. member) -> column (e.g. 'k=2', 'k=3', 'k=4', 'mean') -> TPKL
    in nats, for the last population. ``uniqueness_table``: row -> column (e.g. 's=8',
    's=16', 'mean') -> percent. ``notes``: extra markdown paragraphs (commands, paths).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ReportError(f'run directory {run_dir} does not exist')
    store = RunStore(run_dir.parent, run_dir.name)
    try:
        generation_rows = store.read_rows('generation')
    except RunStoreError as err:
        raise ReportError(f'cannot read the metrics of {run_dir}: {err}') from err
    if not generation_rows:
        raise ReportError(f'{run_dir} has no generation rows in metrics.jsonl yet')
    report_dir = store.report_dir
    report_dir.mkdir(parents=True, exist_ok=True)
    rows = _sorted_rows(generation_rows)
    first, last = rows[0], rows[-1]

    lines = [f'# {title or "SESS-GAN campaign " + run_dir.name}', '']
    config = store.read_config() if store.config_path.exists() else None
    if config is not None:
        lines += [f'Seed {config.get("seed")}, software version '
                  f'{config.get("software_version")}; generations {first["generation"]}'
                  f'..{last["generation"]}.', '']
    lines += faults_found_lines(store.read_rows('episode'), rows, report_dir)
    lines += ['## Summary', '', _summary_table(first, last), '']

    plot_generation_metrics(rows, report_dir / 'generation_metrics.png')
    plot_search_progress(rows, report_dir / 'search_progress.png')
    lines += ['## Risk metrics per generation', '',
              'Population mean over feasible maps and the fittest member '
              "(the paper's Fig. 10).", '',
              '![risk metrics per generation](generation_metrics.png)', '',
              '## Search progress', '',
              '![fitness, feasibility and TPKL](search_progress.png)', '']
    if maps_by_generation:
        plot_maps(maps_by_generation, report_dir / 'maps.png', token_names)
        lines += ['## Sample maps', '',
                  'Generations ' + ', '.join(str(g) for g in sorted(maps_by_generation))
                  + " (the paper's Fig. 9).", '', '![sample maps](maps.png)', '']
    if tpkl_table:
        plot_table(tpkl_table, report_dir / 'tpkl.png', 'TPKL of the last population (nats)')
        lines += ['## TPKL of the last population', '', markdown_table(tpkl_table), '',
                  '![TPKL](tpkl.png)', '']
    if uniqueness_table:
        plot_table(uniqueness_table, report_dir / 'uniqueness.png',
                   'Uniqueness of the last population (%)', '{:.2f}')
        lines += ['## Uniqueness of the last population (%)', '',
                  markdown_table(uniqueness_table, value_format='{:.2f}'), '',
                  '![uniqueness](uniqueness.png)', '']
    for note in notes:
        lines += [note, '']
    path = report_dir / 'report.md'
    path.write_text('\n'.join(lines).rstrip() + '\n', encoding='utf-8')
    return path


def faults_found_lines(episode_rows: Sequence[Mapping[str, Any]],
                       generation_rows: Sequence[Mapping[str, Any]],
                       report_dir: Path) -> list[str]:
    """The report's lead: valid failures and distinct faults found, per episode of the
    robot under test, and faults_found.png (nothing for a run recorded without fault
    labels)."""
    if not episode_rows or 'fault' not in episode_rows[0]:
        return []
    tally = FaultTally.from_rows(episode_rows)
    plot_faults_found(generation_rows, report_dir / 'faults_found.png')
    # The episode's number counts from 1, its id (and its bag's name) from 0: name both.
    first = ('none' if tally.first_failure is None
             else f'episode {tally.first_failure} '
                  f'(`{episode_rows[tally.first_failure - 1].get("environment_id")}`)')
    fault_risks = [row.get('mean_fault_risk_score') for row in generation_rows]
    lines = ['## Faults found', '',
             f'**{tally.valid_failures} valid failures and {tally.distinct_faults} distinct '
             f'faults in {tally.episodes} episodes of the robot under test** '
             f'({tally.per_episode(tally.valid_failures):.3f} and '
             f'{tally.per_episode(tally.distinct_faults):.3f} per episode); first valid '
             f'failure: {first}. Mean fault risk {_fmt(fault_risks[0])} (generation '
             f'{generation_rows[0]["generation"]}) -> {_fmt(fault_risks[-1])} (generation '
             f'{generation_rows[-1]["generation"]}).', '',
             'Distinct faults as `compare` counts them (sessgan_evolver.faults: same kind, '
             'same coarse cell, same map around it); a campaign re-runs nothing, so they are '
             'not confirmed.']
    if tally.situations_counted:
        lines[-1] += (f' They are **{tally.fault_situations} fault situations**: a small '
                      'variant of a failing map that fails at the same place is a new distinct '
                      'fault but the same situation (same kind and coarse cell on maps that '
                      'differ in fewer than 10 % of their cells).')
    if tally.unplaced:
        lines[-1] += (f' {tally.unplaced} valid failures could not be placed (no failure '
                      'bag to read their contacts from) and are not among the distinct '
                      'faults.')
    return lines + ['', *failure_kind_lines(episode_rows), '![faults found](faults_found.png)',
                    '', *origin_lines(episode_rows)]


def origin_lines(episode_rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Where a search method's faults come from: per origin of its episodes (fresh samples,
    children by each operator, ...; sessgan_evolver.fault_tally.origin_family), the episodes
    and the share that were the first to show a distinct fault and a new fault situation
    (nothing for a run whose episodes have no origin: the paper's weight evolution)."""
    if not episode_rows or 'origin' not in episode_rows[0]:
        return []
    tally = FaultTally()
    table: dict[str, OriginFigures] = {}
    for row in episode_rows:
        known = len(tally.faults)
        tally.add(str(row.get('fault') or ''))
        figures = table.setdefault(origin_family(str(row.get('origin') or '')), OriginFigures())
        figures.episodes += 1
        figures.faults += len(tally.faults) > known
        figures.situations += row.get('situation') is True
    lines = ['Where they come from, per origin of the episodes:', '',
             '| episodes from | episodes | new distinct fault | new fault situation |',
             '|---|---:|---:|---:|', *origin_rows(table)]
    return lines + ['']


FAULT_KIND_MEANINGS = {
    'collision_static': 'drove into a wall, barrier or low obstacle',
    'collision_agent': 'drove into an agent',
    'collision_robot': 'drove into another robot under test',
    'stuck': 'neither closer to the goal nor onto new ground for the stuck window',
    'timeout': 'the goal not reached within the time limit',
    UNPLACED: 'no failure bag to place it by',
}
"""What each fault kind of an episode's ``fault`` label means (sessgan_evolver.faults)."""


def failure_kind_lines(episode_rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """A table of the valid failures by fault kind: a stack that stops in narrow passages
    and one that clips wall corners have different bugs."""
    kinds: dict[str, tuple[int, set[str], str]] = {}
    for row in episode_rows:
        label = str(row.get('fault') or '')
        if not label:
            continue
        kind = label if label == UNPLACED else label.rpartition('-r')[0]
        count, labels, first = kinds.get(kind, (0, set(), str(row.get('environment_id'))))
        kinds[kind] = (count + 1, labels | {label}, first)
    if not kinds:
        return []
    lines = ['| fault kind | what | valid failures | distinct faults | first episode |',
             '|---|---|---:|---:|---|']
    for kind, (count, labels, first) in sorted(kinds.items(), key=lambda item: -item[1][0]):
        distinct = 0 if kind == UNPLACED else len(labels)
        lines.append(f'| `{kind}` | {FAULT_KIND_MEANINGS.get(kind, "")} | {count} | '
                     f'{distinct} | `{first}` |')
    return [*lines, '']


def plot_faults_found(generation_rows: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Two panels: valid failures and distinct faults so far against episodes so far;
    mean fault risk and the paper's mean risk per generation."""
    rows = _sorted_rows(generation_rows)
    # From the origin: nothing is found before the first episode.
    episodes = [0.0] + _column(rows, 'episodes_so_far')
    figure, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    axes[0].plot(episodes, [0.0] + _column(rows, 'valid_failures_so_far'), marker='o',
                 markersize=3, label='valid failures')
    axes[0].plot(episodes, [0.0] + _column(rows, 'distinct_faults_so_far'), marker='o',
                 markersize=3, label='distinct faults')
    if all('fault_situations_so_far' in row for row in rows):
        axes[0].plot(episodes, [0.0] + _column(rows, 'fault_situations_so_far'), marker='o',
                     markersize=3, label='fault situations')
    axes[0].set_xlabel('Episodes of the robot under test')
    axes[0].set_ylabel('Found so far')
    axes[0].legend(fontsize='small')
    generations = [row['generation'] for row in rows]
    axes[1].plot(generations, _column(rows, 'mean_fault_risk_score'), marker='o',
                 markersize=3, label='fault risk')
    axes[1].plot(generations, _column(rows, 'mean_risk_score'), marker='.', markersize=3,
                 linestyle='--', label="risk (paper's, all collisions)")
    axes[1].set_xlabel('Generation')
    axes[1].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[1].set_ylabel('Mean over feasible maps')
    axes[1].legend(fontsize='small')
    for axis in axes:
        axis.grid(alpha=0.3)
    return _save(figure, path)


# -- helpers --------------------------------------------------------------------------------


def _summary_table(first: Mapping[str, Any], last: Mapping[str, Any]) -> str:
    metrics = [('valid_failures_so_far', 'valid failures so far'),
               ('distinct_faults_so_far', 'distinct faults so far'),
               ('fault_situations_so_far', 'fault situations so far'),
               ('mean_fault_risk_score', 'mean fault risk score'),
               ('mean_risk_score', 'mean risk score'), ('max_risk_score', 'max member risk'),
               ('mean_collisions', 'mean collisions'),
               ('mean_proximity_time', 'mean proximity time (s)'),
               ('mean_simulation_time', 'mean simulation time (s)'),
               ('feasible_fraction', 'feasible fraction'), ('mean_tpkl', 'mean TPKL (nats)'),
               ('mean_fitness', 'mean fitness'), ('best_fitness', 'best fitness')]
    lines = [f'| metric | generation {first["generation"]} | generation {last["generation"]}'
             ' | ratio |', '|---|---:|---:|---:|']
    for key, label in metrics:
        a, b = first.get(key), last.get(key)
        ratio = ''
        if key.endswith('_so_far') and a is None:
            continue  # a run recorded before faults (or situations) were counted
        # Fitness can be negative, so a ratio of fitnesses means nothing; nor does one of
        # counts so far (the first generation's are a part of the last's).
        if key not in ('mean_fitness', 'best_fitness') and not key.endswith('_so_far') \
                and isinstance(a, (int, float)) \
                and isinstance(b, (int, float)) and a > 0:
            ratio = f'{b / a:.2f}x'
        lines.append(f'| {label} | {_fmt(a)} | {_fmt(b)} | {ratio} |')
    return '\n'.join(lines)


def _fmt(value: Any) -> str:
    if value is None:
        return '–'
    if isinstance(value, float):
        return f'{value:.4g}'
    return str(value)


def _sorted_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    if not rows:
        raise ReportError('no generation rows to plot')
    return sorted(rows, key=lambda row: int(row['generation']))


def _column(rows: Sequence[Mapping[str, Any]], key: str) -> list[float]:
    """Values of ``key`` as floats; missing or null values become NaN (gaps in the plot)."""
    return [math.nan if row.get(key) is None else float(row[key]) for row in rows]


def _map_colours(values: np.ndarray, token_names: Sequence[str] | None
                 ) -> tuple[ListedColormap, BoundaryNorm, list[tuple[str, str]]]:
    if set(values.tolist()) <= set(OCCUPANCY_COLOURS) and token_names is None:
        keys = sorted(OCCUPANCY_COLOURS)
        colours = [OCCUPANCY_COLOURS[k] for k in keys]
        labels = {0: 'free', 50: 'low obstacle', 100: 'wall / out of bounds'}
        legend = [(labels[k], OCCUPANCY_COLOURS[k]) for k in keys if k in set(values.tolist())]
        bounds = [-0.5, 25, 75, 100.5]
        return ListedColormap(colours), BoundaryNorm(bounds, len(colours)), legend
    count = max(int(values.max()) + 1, len(token_names or ()))
    if count > len(TOKEN_COLOURS) or values.min() < 0:
        raise ReportError(f'maps hold values {values.tolist()[:10]}: neither OccupancyGrid '
                          f'values nor token ids below {len(TOKEN_COLOURS)}')
    colours = list(TOKEN_COLOURS[:count])
    names = list(token_names) if token_names else [f'token {i}' for i in range(count)]
    bounds = [i - 0.5 for i in range(count + 1)]
    return (ListedColormap(colours), BoundaryNorm(bounds, count),
            list(zip(names, colours)))


def _table_arrays(table: Mapping[str, Mapping[str, float]]
                  ) -> tuple[list[str], list[str], np.ndarray]:
    if not table:
        raise ReportError('empty table')
    row_labels = [str(label) for label in table]
    column_labels: list[str] = []
    for row in table.values():
        for column in row:
            if str(column) not in column_labels:
                column_labels.append(str(column))
    values = np.full((len(row_labels), len(column_labels)), math.nan)
    for i, row in enumerate(table.values()):
        for column, value in row.items():
            values[i, column_labels.index(str(column))] = (math.nan if value is None
                                                           else float(value))
    return row_labels, column_labels, values


def _save(figure: Any, path: str | Path, bottom: float = 0.0) -> Path:
    """Lay out, write as PNG and close; ``bottom``: fraction of the height kept free."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout(rect=(0.0, bottom, 1.0, 1.0))
    figure.savefig(path, dpi=FIGURE_DPI)
    plt.close(figure)
    return path
