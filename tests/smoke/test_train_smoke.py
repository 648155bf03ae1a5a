"""Smoke: the real `train` entry point on a tiny budget, then resume and sampling."""

from __future__ import annotations

import json

import pytest
import torch

from sessgan_gen.checkpoint import load_checkpoint
from sessgan_gen.train_cli import main

pytestmark = pytest.mark.smoke
torch.set_num_threads(1)

TINY_FACTORY = '\n'.join([
    '# scenario: factory',
    'WWWWWWWWWWWWWWWW',
    'WGGGGGGWGGGGGGGW',
    'WGWWGGGWGGGWWGGW',
    'WGWWGGGGGGGWWGGW',
    'WGGGGGGWGGGGGGGW',
    'WWWGWWWWWWGWWWWW',
    'WGGGGGGGGGGGGGGW',
    'WGGWWWGGGGGWWGGW',
    'WGGWWWGGWGGWWGGW',
    'WGGGGGGGWGGGGGGW',
    'WGGGGGGGWGGGGGGW',
    'WWWWGGWWWWWGGWWW',
    'WGGGGGGGGGGGGGGW',
    'WGGWWGGGGGWWGGGW',
    'WGGGGGGGGGGGGGGW',
    'WWWWWWWWWWWWWWWW',
]) + '\n'


def test_train_writes_a_checkpoint_that_loads_and_samples(tmp_path, capsys):
    map_file = tmp_path / 'tiny.txt'
    map_file.write_text(TINY_FACTORY)
    output = tmp_path / 'out' / 'tiny.pt'
    argv = ['--scenario', 'factory', '--map-file', str(map_file), '--iterations', '3',
            '--channels', '4', '--output', str(output), '--seed', '5', '--threads', '1']
    assert main(argv) == 0
    metadata = json.loads(output.with_suffix('.json').read_text())
    assert metadata['complete'] is True and metadata['scenario'] == 'factory'
    assert metadata['scale_shapes'] == [[8, 8], [16, 16]]
    assert metadata['training_config']['iterations'] == 3
    assert metadata['seed'] == 5 and metadata['training_seconds'] > 0
    pyramid, _ = load_checkpoint(output, scenario='factory')
    assert pyramid.sample(seeds=[0, 1], size=(24, 24)).shape == (2, 24, 24)
    stderr = capsys.readouterr().err
    assert 'scale 2/2' in stderr and 'it/s' in stderr and 'ETA' in stderr

    # Resuming a finished run does nothing; a changed option is refused.
    assert main(argv + ['--resume']) == 0
    assert 'already complete' in capsys.readouterr().err
    assert main(argv + ['--resume', '--seed', '6']) == 2  # a usage error: nothing written
    assert 'seed' in capsys.readouterr().err


def test_train_reports_bad_input_clearly(tmp_path, capsys):
    # Inputs the options name that cannot be used are usage errors: exit 2, nothing written.
    assert main(['--map-file', str(tmp_path / 'missing.txt'), '--output',
                 str(tmp_path / 'x.pt')]) == 2
    assert 'missing.txt' in capsys.readouterr().err
    map_file = tmp_path / 'tiny.txt'
    map_file.write_text(TINY_FACTORY)
    assert main(['--scenario', 'drone', '--map-file', str(map_file), '--output',
                 str(tmp_path / 'x.pt')]) == 2
    assert 'factory' in capsys.readouterr().err
    assert main(['--map-file', str(map_file), '--output', str(tmp_path / 'y.pt'),
                 '--resume']) == 2
    assert 'does not exist' in capsys.readouterr().err
    assert sorted(path.name for path in tmp_path.iterdir()) == ['tiny.txt']
