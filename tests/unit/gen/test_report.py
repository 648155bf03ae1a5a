"""The environment-metrics report: TPKL matrix, uniqueness table, files written."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sessgan_core.scenarios import get_scenario
from sessgan_gen.checkpoint import save_checkpoint
from sessgan_gen.model import GeneratorPyramid, pyramid_scale_shapes
from sessgan_gen.report import (
    PAPER_UNIQUENESS,
    REPORT_SCENARIOS,
    ReportData,
    ScenarioSamples,
    compute_report,
    tpkl_markdown,
    tpkl_matrix,
    uniqueness_markdown,
    write_report,
)
from sessgan_gen.report_cli import main

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


@pytest.fixture(scope='module')
def checkpoints(tmp_path_factory) -> dict[str, str]:
    """Untrained 16x16 pyramids of each scenario: enough to exercise the report quickly."""
    folder = tmp_path_factory.mktemp('checkpoints')
    paths = {}
    for index, name in enumerate(REPORT_SCENARIOS):
        spec = get_scenario(name)
        torch.manual_seed(index)
        pyramid = GeneratorPyramid(spec.num_tokens, pyramid_scale_shapes(16, 16), channels=4)
        pyramid.noise_amplitudes.fill_(1.0)
        metadata = {'scenario': name, 'tokens': list(spec.tokens), 'complete': True}
        paths[name] = str(save_checkpoint(folder / f'{name}.pt', pyramid, metadata))
    return paths


def samples(name: str, maps: np.ndarray, example: np.ndarray) -> ScenarioSamples:
    return ScenarioSamples(name, maps, example, [True] * len(maps), '', {}, 0.0)


def test_tpkl_matrix_rows_are_generated_maps_and_columns_examples():
    walls = np.zeros((12, 12), dtype=np.int64)
    walls[::3] = 1
    empty = np.zeros((12, 12), dtype=np.int64)
    items = [samples('factory', np.stack([walls, walls]), walls),
             samples('drone', np.stack([empty, empty]), empty)]
    matrix = tpkl_matrix(items)
    assert matrix.shape == (2, 2)
    assert matrix[0, 0] == pytest.approx(0.0, abs=1e-6)  # identical statistics
    assert matrix[1, 1] == pytest.approx(0.0, abs=1e-6)
    assert matrix[0, 1] > 1.0 and matrix[1, 0] > 1.0


def test_compute_and_write_the_report(checkpoints, tmp_path):
    data = compute_report(REPORT_SCENARIOS, checkpoints, count=3, seed=1)
    assert data.tpkl.shape == (3, 3) and np.isfinite(data.tpkl).all()
    assert set(data.uniqueness) == set(REPORT_SCENARIOS)
    for name in REPORT_SCENARIOS:
        assert data.samples[name].maps.shape == (3, 16, 16)
        # 16x16 maps hold one 16x16 patch each: uniqueness = distinct maps / maps.
        maps = data.samples[name].maps
        distinct = len({m.tobytes() for m in maps})
        assert data.uniqueness[name][16] == pytest.approx(100.0 * distinct / len(maps))
    written = write_report(data, tmp_path / 'report')
    names = sorted(path.name for path in written)
    assert names == sorted(['tpkl_matrix.md', 'uniqueness.md', 'tpkl_matrix.png',
                            'uniqueness.png', 'samples_factory.png', 'samples_racetrack.png',
                            'samples_drone.png', 'report.md', 'metrics.json'])
    for path in written:
        assert path.stat().st_size > 0
    assert (tmp_path / 'report' / 'tpkl_matrix.png').read_bytes()[:4] == b'\x89PNG'
    metrics = json.loads((tmp_path / 'report' / 'metrics.json').read_text())
    assert metrics['paper_uniqueness_percent']['racetrack']['16'] == 95.60
    assert len(metrics['tpkl_matrix']['values']) == 3


def test_markdown_shows_the_paper_figures_beside_ours():
    maps = np.zeros((2, 16, 16), dtype=np.int64)
    maps[1, 3] = 1
    items = {name: samples(name, maps, maps[1]) for name in REPORT_SCENARIOS}
    data = ReportData(list(REPORT_SCENARIOS), 2, 0, items, np.eye(3) + 0.5,
                      {name: {8: 50.0, 16: 99.0} for name in REPORT_SCENARIOS})
    table = uniqueness_markdown(data)
    for name, paper in PAPER_UNIQUENESS.items():
        assert f'| {name} | 50.00 | {paper["8"]:.2f} | 99.00 | {paper["16"]:.2f} |' in table
    assert '| drone | 50.00 | 33.00 | 99.00 | 98.20 | 74.50 | 91.27 | yes | 100 % |' in table
    matrix = tpkl_markdown(data)
    assert '| factory | 1.500 | **0.500** | **0.500** |' in matrix
    assert 'factory NO' in matrix  # the diagonal is not strictly lowest here


def test_report_command_writes_into_the_output_directory(checkpoints, tmp_path, capsys):
    argv = ['--output-dir', str(tmp_path / 'out'), '--samples', '2', '--threads', '1']
    for name, path in checkpoints.items():
        argv += [f'--{name}-checkpoint', path]
    assert main(argv) == 0
    assert (tmp_path / 'out' / 'report.md').exists()
    assert 'Uniqueness' in capsys.readouterr().out
    # A checkpoint that is not there is a usage error: exit 2, nothing written.
    assert main(['--output-dir', str(tmp_path / 'bad'), '--samples', '2',
                 '--factory-checkpoint', str(tmp_path / 'missing.pt')]) == 2
    assert not (tmp_path / 'bad').exists()
