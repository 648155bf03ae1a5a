"""Smoke: your own map from the command line (`train --map-yaml`) and `export` of any map, with
a tiny training budget."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sessgan_core.map_server_io import read_map_server, write_map_server
from sessgan_core.token_map import read_token_map, tokens_to_occupancy
from sessgan_gen.export_cli import main as export_main
from sessgan_gen.train_cli import main as train_main
from tests.unit.core.test_map_server_io import write_negated_facility

pytestmark = pytest.mark.smoke
torch.set_num_threads(1)


def test_train_on_a_map_server_map_and_export_its_maps(tmp_path, capsys):
    (tmp_path / 'input').mkdir()
    yaml_path, expected = write_negated_facility(tmp_path / 'input')
    output = tmp_path / 'out' / 'facility.pt'
    assert train_main(['--scenario', 'factory', '--map-yaml', str(yaml_path), '--iterations',
                       '2', '--channels', '4', '--output', str(output), '--seed', '3',
                       '--threads', '1', '--no-progress']) == 0
    stderr = capsys.readouterr().err
    assert '16x12 cells of 0.5 m' in stderr

    # The map as learned, next to the checkpoint: tokens and a map_server map to look at.
    learned = read_token_map(output.with_suffix('.map.txt'))
    np.testing.assert_array_equal(learned.cells, expected)
    as_map = read_map_server(output.with_suffix('.map.yaml'))
    assert as_map.resolution == 0.5
    np.testing.assert_array_equal(as_map.occupancy, tokens_to_occupancy(expected, 'factory'))
    metadata = json.loads(output.with_suffix('.json').read_text())
    assert metadata['map_source'] == str(yaml_path.resolve())
    assert metadata['training_config']['map_yaml'] == str(yaml_path)

    # Export: the token map, a map the new checkpoint generates, a failure bag's map.
    exported = tmp_path / 'exports'
    assert export_main(['--map-file', str(output.with_suffix('.map.txt')), '--output',
                        str(exported / 'learned.yaml')]) == 0
    np.testing.assert_array_equal(read_map_server(exported / 'learned.yaml').occupancy,
                                  as_map.occupancy)
    assert export_main(['--generate', '--checkpoint', str(output), '--seed', '5', '--width',
                        '20', '--height', '14', '--output', str(exported / 'generated.yaml')]) == 0
    generated = read_map_server(exported / 'generated.yaml')
    assert generated.occupancy.shape == (14, 20) and generated.resolution == 0.5
    assert set(np.unique(generated.occupancy)) <= {0, 100}
    bag = tmp_path / 'bags' / 'g001-m02-s5'
    bag.mkdir(parents=True)
    write_map_server(bag / 'map.yaml', tokens_to_occupancy(expected, 'factory'), 0.5,
                     (1.5, -2.0, 0.0))
    assert export_main(['--bag', str(bag), '--output', str(exported / 'failing.yaml')]) == 0
    failing = read_map_server(exported / 'failing.yaml')
    assert failing.origin == (1.5, -2.0, 0.0)
    np.testing.assert_array_equal(failing.occupancy, as_map.occupancy)
    assert (exported / 'failing.pgm').is_file()


def test_map_commands_report_bad_input_clearly(tmp_path, capsys):
    yaml_path, _ = write_negated_facility(tmp_path)
    # Bad options, and inputs they name that cannot be used, are usage errors: exit 2,
    # nothing written.
    assert train_main(['--map-yaml', str(yaml_path), '--map-file', 'x.txt', '--output',
                       str(tmp_path / 'x.pt')]) == 2
    assert 'not both' in capsys.readouterr().err
    assert train_main(['--map-yaml', str(tmp_path / 'missing.yaml'), '--output',
                       str(tmp_path / 'x.pt')]) == 2
    assert 'missing.yaml' in capsys.readouterr().err
    assert not (tmp_path / 'x.pt').exists()
    assert export_main(['--output', str(tmp_path / 'a.yaml')]) == 2
    assert 'exactly one of' in capsys.readouterr().err
    assert export_main(['--generate', '--bag', str(tmp_path), '--output',
                        str(tmp_path / 'a.yaml')]) == 2
    assert 'got --generate, --bag' in capsys.readouterr().err
    assert export_main(['--bag', str(tmp_path), '--output', str(tmp_path / 'a.yaml')]) == 2
    assert 'no map.yaml' in capsys.readouterr().err
    assert export_main(['--bag', str(tmp_path), '--output', str(tmp_path / 'a.pgm')]) == 2
    assert 'must name a .yaml' in capsys.readouterr().err
