"""The campaign report: Fig. 10 and Fig. 9 style plots, tables and report.md."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_evolver.errors import ReportError
from sessgan_evolver.report import markdown_table, report_generations, write_report
from sessgan_evolver.run_store import RunStore

pytestmark = pytest.mark.unit


def fill_run(store: RunStore, generations: int) -> None:
    store.write_config({'scenario': 'factory', 'generations': generations}, seed=3)
    for generation in range(generations):
        store.append_generation({
            'generation': generation, 'members': 4, 'episodes': 12,
            'feasible_fraction': 0.9 + 0.01 * (generation % 3), 'mean_fitness': 0.1 * generation,
            'best_fitness': 0.2 + 0.1 * generation, 'best_member': generation % 4,
            'mean_risk_score': 0.1 + 0.02 * generation, 'best_risk_score': 0.3,
            'max_risk_score': 0.4, 'mean_collisions': 0.5, 'best_collisions': 1.0,
            'mean_proximity_time': 2.0, 'best_proximity_time': None,
            'mean_simulation_time': 20.0 - generation, 'best_simulation_time': 15.0,
            'mean_tpkl': 0.2 + 0.01 * generation, 'tpkl_reference': 0.2,
            'mean_diversity': 0.3})


def test_report_generations_are_0_25_50_100_percent():
    assert report_generations(29) == [0, 7, 14, 29]
    assert report_generations(2) == [0, 1, 2]
    assert report_generations(0) == [0]
    with pytest.raises(ReportError):
        report_generations(-1)


def test_write_report_makes_every_figure_and_the_markdown(tmp_path):
    store = RunStore(tmp_path, 'run')
    fill_run(store, 9)
    rng = np.random.default_rng(0)
    maps = {g: [np.where(rng.random((8, 8)) < 0.3, 100, 0).astype(np.int8) for _ in range(3)]
            for g in report_generations(8)}
    maps[8][0][2, 2] = 50
    tpkl = {f'member {m}': {'k=2': 0.1 * m, 'k=3': 0.2, 'k=4': 0.3, 'mean': 0.2}
            for m in range(3)}
    uniqueness = {'last population': {'s=8': 91.3, 's=16': 88.0, 'mean': 89.65}}
    path = write_report(store.run_dir, maps, tpkl, uniqueness,
                        notes=['Replay a bag: `ros2 run sessgan_evolver replay bags/run/x`'])
    assert path == store.run_dir / 'report' / 'report.md'
    for name in ('generation_metrics.png', 'search_progress.png', 'maps.png', 'tpkl.png',
                 'uniqueness.png'):
        image = store.report_dir / name
        assert image.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n', name
        assert f']({name})' in path.read_text()
    text = path.read_text()
    assert '| mean risk score | 0.1 | 0.26 | 2.60x |' in text
    assert '| member 2 | 0.200 | 0.200 | 0.300 | 0.200 |' in text
    assert '| last population | 91.30 | 88.00 | 89.65 |' in text
    assert 'Generations 0, 2, 4, 8' in text and 'ros2 run sessgan_evolver replay' in text


def test_token_maps_are_drawn_with_their_names(tmp_path):
    store = RunStore(tmp_path, 'run')
    fill_run(store, 2)
    maps = {0: [np.array([[0, 1], [2, 0]])], 1: [np.array([[0, 0], [1, 2]]),
                                                 np.array([[1, 1], [1, 1]])]}
    write_report(store.run_dir, maps, token_names=('ground', 'wall', 'low obstacle'))
    assert (store.report_dir / 'maps.png').stat().st_size > 1000


def test_a_run_without_generation_rows_is_an_error(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.append_episode({'generation': 0, 'member': 0})
    with pytest.raises(ReportError, match='no generation rows'):
        write_report(store.run_dir)
    with pytest.raises(ReportError, match='does not exist'):
        write_report(tmp_path / 'missing')


def test_markdown_table_fills_missing_cells():
    table = {'a': {'x': 1.0}, 'b': {'y': 2.0}}
    assert markdown_table(table, corner='row').splitlines() == [
        '| row | x | y |', '|---|---:|---:|', '| a | 1.000 |  |', '| b |  | 2.000 |']
