"""What ``compare`` shows (console, report table, compare.png, failing_maps.png) claims no
more than it measured: one shared generator is one measurement, whiskers stay inside what a
quantity can take, the caption names only the methods run, the titles are legible."""

from __future__ import annotations

import re

import matplotlib
import numpy as np
import pytest
import torch
from matplotlib.collections import LineCollection

from sessgan_evolver.comparison import (
    REPORTED,
    CompareConfig,
    MethodRun,
    RunFigures,
    comparison_figure,
    method_table,
    run_comparison,
)
from sessgan_evolver.fault_picture import FaultScene, scene_grid_figure

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

pytestmark = pytest.mark.unit
torch.set_num_threads(1)

LABELS = {key: label for key, label, _ in REPORTED}


def figures(method, seed, **values):
    base = dict(method=method, search_seed=seed, episodes=12, valid_maps=12, valid_failures=2,
                distinct_faults=2, checked_faults=2, confirmed_faults=2, exact_faults=2,
                confirmed_per_1000=166.7, distinct_per_1000=166.7, first_confirmed_episode=3,
                first_confirmed_wall=1.0, first_confirmed_cpu=1.0, search_wall=2.0,
                search_cpu=2.0, generator='shipped generator', fresh_failure_rate=1 / 3,
                fresh_valid_fraction=1.0, failing_tpkl=1.7, failing_uniqueness=100.0)
    base.update(values)
    return RunFigures(**base)


def runs_of(*rows):
    """MethodRuns from (method, seed, source_key, RunFigures values) without episodes."""
    return [MethodRun(figures(method, seed, **values), [], [], None, key)
            for method, seed, key, values in rows]


def panel(figure, key):
    title = LABELS[key]
    return next(axis for axis in figure.axes if axis.get_title().startswith(title))


def dots(axis, index):
    """y of the measurement dots drawn at x = index."""
    return [float(y) for line in axis.get_lines() if line.get_marker() == 'o'
            for x, y in zip(line.get_xdata(), line.get_ydata()) if x == index]


def whiskers(axis):
    """y of every error-bar segment drawn on ``axis``."""
    return [float(y) for collection in axis.collections if isinstance(collection, LineCollection)
            for segment in collection.get_segments() for _, y in segment]


def every_text(figure):
    texts = [figure._suptitle.get_text()] if figure._suptitle else []
    return '\n'.join(texts + [text.get_text() for axis in figure.axes for text in axis.texts])


def test_one_shared_generator_is_one_measurement_without_spread():
    """random leaves the shipped generator on every seed, evaluated once: 0.333 (n=1), one
    dot, no whisker; SESS-GAN's two seeds left two generators: two measurements."""
    config = CompareConfig(methods=('sessgan', 'random'), search_seeds=(0, 1))
    runs = runs_of(('sessgan', 0, 'sessgan:a', {'fresh_failure_rate': 0.2}),
                   ('random', 0, 'pyramid:base', {}),
                   ('sessgan', 1, 'sessgan:b', {'fresh_failure_rate': 0.4}),
                   ('random', 1, 'pyramid:base', {}))
    row = next(line for line in method_table(config, runs).splitlines()
               if LABELS['fresh_failure_rate'] in line)
    cells = [cell.strip() for cell in row.strip('|').split('|')][1:]
    assert cells == ['0.300 ± 0.141', '0.333 (n=1)']
    figure = comparison_figure(config, runs)
    try:
        axis = panel(figure, 'fresh_failure_rate')
        assert dots(axis, 0) == pytest.approx([0.2, 0.4])
        assert dots(axis, 1) == pytest.approx([1 / 3])
        assert 'n=1' in [text.get_text() for text in axis.texts]
        assert whiskers(axis) == pytest.approx([0.2, 0.4])  # SESS-GAN's only
        # The per-run figures still count both of random's runs.
        assert dots(panel(figure, 'confirmed_per_1000'), 1) == pytest.approx([166.7, 166.7])
    finally:
        plt.close(figure)


def test_whiskers_stay_inside_what_the_quantity_can_take():
    """mean ± std of 100 % and 94 % reached 101 %; of episodes 1 and 5, 0.17 episodes."""
    config = CompareConfig(methods=('random', 'latent'), search_seeds=(0, 1))
    runs = runs_of(('random', 0, 'pyramid:base', {'failing_uniqueness': 100.0,
                                                  'first_confirmed_episode': 1}),
                   ('latent', 0, 'pyramid:base', {}),
                   ('random', 1, 'pyramid:base', {'failing_uniqueness': 94.0,
                                                  'first_confirmed_episode': 5}),
                   ('latent', 1, 'pyramid:base', {}))
    figure = comparison_figure(config, runs)
    try:
        uniqueness = whiskers(panel(figure, 'failing_uniqueness'))
        assert uniqueness and min(uniqueness) == pytest.approx(94.0)
        assert max(uniqueness) == pytest.approx(100.0)
        episodes = whiskers(panel(figure, 'first_confirmed_episode'))
        assert episodes and min(episodes) == pytest.approx(1.0)
        assert max(episodes) == pytest.approx(5.0)
        assert 'whiskers: min–max' in figure._suptitle.get_text()
    finally:
        plt.close(figure)


def test_the_caption_names_only_the_methods_run():
    runs = runs_of(('random', 0, 'pyramid:base', {}), ('latent', 0, 'pyramid:base', {}))
    figure = comparison_figure(CompareConfig(methods=('random', 'latent'), search_seeds=(0,)),
                               runs)
    try:
        caption = every_text(figure)
        assert 'SESS-GAN' not in caption and '12 x 3' not in caption
        assert 'GA population 12 (latent)' in caption
    finally:
        plt.close(figure)
    figure = comparison_figure(CompareConfig(methods=('sessgan',), search_seeds=(0,)),
                               runs_of(('sessgan', 0, 'sessgan:a', {})))
    try:
        assert 'SESS-GAN: 12 x 3' in every_text(figure)
        assert 'GA population' not in every_text(figure)
    finally:
        plt.close(figure)


def test_a_shared_generator_is_reported_once_and_formatted(tmp_path):
    """End to end: the console's fresh-seed line has 3 decimals and says whose generator it
    is; the report's table says n=1 without a spread; fresh_seed.csv has its one row."""
    config = CompareConfig(methods=('random', 'latent'), search_seeds=(0, 1), budget=3,
                           time_limit=2.0, fresh_episodes=3, repeats=1, max_fault_records=0)
    lines: list[str] = []
    run_comparison(config, tmp_path / 'compare', 'compare --tiny', log=lines.append)
    fresh = [line for line in lines if line.startswith('fresh seeds')]
    assert len(fresh) == 1
    assert re.fullmatch(r'fresh seeds, shipped generator \(left by random, latent: one '
                        r'evaluation for their 4 runs\): failure rate \d\.\d{3}, \d+ valid maps',
                        fresh[0]), fresh[0]
    report = (tmp_path / 'compare' / 'report.md').read_text()
    row = next(line for line in report.splitlines() if LABELS['fresh_failure_rate'] in line)
    assert '±' not in row and row.count('(n=1)') == 2
    assert 'SESS-GAN' not in report.split('## How it is counted')[1]
    assert len((tmp_path / 'compare' / 'fresh_seed.csv').read_text().splitlines()) == 2


def scene(caption):
    occupancy = np.zeros((20, 20), dtype=np.int8)
    occupancy[0, :] = occupancy[-1, :] = occupancy[:, 0] = occupancy[:, -1] = 1
    return FaultScene('factory', occupancy, 0.5, (0.0, 0.0), (2.0, 2.0), (8.0, 8.0),
                      np.array([[2.0, 2.0], [5.0, 5.0]]), caption=caption,
                      route=np.array([[2.0, 2.0], [8.0, 8.0]]), fault_place=(5.0, 5.0))


def test_the_second_rows_titles_clear_the_first_row():
    rows = [('random', [scene(f'seed {i}: collision static') for i in range(4)]),
            ('latent', [scene(f'seed {i}: collision static') for i in range(4)])]
    figure = scene_grid_figure(rows)
    try:
        renderer = figure.canvas.get_renderer()
        figure.draw(renderer)
        axes = np.array(figure.axes).reshape(2, 4)
        for column in range(4):
            above = axes[0][column].get_window_extent(renderer)
            title = axes[1][column].title.get_window_extent(renderer)
            assert title.y1 <= above.y0, (column, title, above)
    finally:
        plt.close(figure)


def test_a_fleet_fault_picture_names_the_robot_that_failed():
    from sessgan_evolver.fault_picture import default_title, fleet_fault_robot

    contacts = [{'kind': 'agent_into_robot', 'fault': False, 'robot': 0, 'x': 0.0, 'y': 0.0},
                {'kind': 'static', 'fault': True, 'robot': 2, 'x': 5.0, 'y': 6.0}]
    assert fleet_fault_robot(contacts, {}, 3) == 2  # the first contact a robot caused
    assert fleet_fault_robot([], {'failed_leg': 1}, 3) == 1  # else the failing robot
    assert fleet_fault_robot(contacts, {'failed_leg': 1}, 1) is None  # one robot: no name
    metrics = {'outcome': 'stuck', 'fault_collisions': 0}
    assert default_title(metrics, None, robot=1).startswith('r1: stuck | ')
    assert default_title(metrics, None).startswith('stuck | ')
