"""Tests of the token map text format and the occupancy conversions."""

from pathlib import Path

import numpy as np
import pytest

from sessgan_core.errors import MapFormatError, UnknownScenarioError
from sessgan_core.scenarios import SCENARIOS, get_scenario
from sessgan_core.token_map import (
    EXAMPLE_MAP_DIR,
    TokenMap,
    format_token_map,
    load_example_map,
    occupancy_to_tokens,
    parse_token_map,
    read_token_map,
    to_common_encoding,
    tokens_to_occupancy,
    write_token_map,
)

pytestmark = pytest.mark.unit

FACTORY_TEXT = """# scenario: factory
# a comment
WWWW
WGGW
WGWW
"""


def test_parse_flips_rows_so_row_zero_is_the_bottom():
    token_map = parse_token_map(FACTORY_TEXT)
    assert token_map.scenario == 'factory'
    assert token_map.cells.shape == (3, 4)
    # The last line of the file is the bottom row (row 0).
    assert token_map.cells[0].tolist() == [1, 0, 1, 1]
    assert token_map.cells[2].tolist() == [1, 1, 1, 1]
    assert token_map.cells.dtype == np.int64
    assert (token_map.height, token_map.width) == (3, 4)


def test_write_then_read_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    cells = rng.integers(0, 3, size=(7, 5))
    path = tmp_path / 'map.txt'
    write_token_map(path, TokenMap('drone', cells))
    again = read_token_map(path)
    assert again.scenario == 'drone'
    np.testing.assert_array_equal(again.cells, cells)
    text = path.read_text()
    assert text.startswith('# scenario: drone\n')
    # Files are written top row first.
    assert text.splitlines()[2] == ''.join('GWO'[v] for v in cells[-1])
    assert not [p for p in tmp_path.iterdir() if p.name != 'map.txt']  # no temp files left


def test_scenario_argument_when_header_missing_and_agreeing():
    cells = parse_token_map('TTO\nOTT\n', scenario='racetrack').cells
    assert cells.tolist() == [[1, 0, 0], [0, 0, 1]]
    assert parse_token_map(FACTORY_TEXT, scenario='factory').scenario == 'factory'


def test_blank_lines_around_rows_and_trailing_spaces_are_allowed():
    token_map = parse_token_map('\n# scenario: factory\n\nGW  \nWG\r\n\n\n')
    assert token_map.cells.tolist() == [[1, 0], [0, 1]]


@pytest.mark.parametrize('text, scenario, pieces', [
    ('# scenario: factory\nGGW\nGXW\n', None, ['line 3, column 2', "'X'", 'factory']),
    ('# scenario: factory\nGGW\nGW\n', None, ['line 3', 'has 2 cells', 'line 2', 'has 3']),
    ('# scenario: factory\n', None, ['empty map']),
    ('', 'factory', ['empty map']),
    ('# scenario: kitchen\nGG\n', None, ['line 1', "unknown scenario 'kitchen'", 'factory']),
    ('GG\n', None, ['no scenario given']),
    ('# scenario: factory\nGG\n', 'drone', ["'factory' map", "'drone' was requested"]),
    ('# scenario: factory\nGG\n\nGG\n', None, ['line 3', 'blank line inside']),
    ('GG\n', 'kitchen', ['unknown scenario']),
])
def test_parse_errors_name_the_problem(text, scenario, pieces):
    with pytest.raises(MapFormatError) as info:
        parse_token_map(text, scenario, source='m.txt')
    message = str(info.value)
    assert message.startswith('m.txt')
    for piece in pieces:
        assert piece in message


def test_read_errors_name_the_file(tmp_path):
    with pytest.raises(MapFormatError, match='does not exist'):
        read_token_map(tmp_path / 'missing.txt')
    bad = tmp_path / 'bad.txt'
    bad.write_bytes(b'# scenario: factory\n\xff\xfe\n')
    with pytest.raises(MapFormatError, match='not UTF-8'):
        read_token_map(bad)
    ragged = tmp_path / 'ragged.txt'
    ragged.write_text('# scenario: factory\nGGG\nGG\n')
    with pytest.raises(MapFormatError, match=f'{ragged}, line 3'):
        read_token_map(ragged)


def test_format_rejects_invalid_token_ids():
    with pytest.raises(MapFormatError, match=r'cell \(row 0, col 1\) holds token id 2'):
        format_token_map(TokenMap('factory', np.array([[0, 2]])))
    with pytest.raises(MapFormatError, match='2-D'):
        format_token_map(TokenMap('factory', np.array([0, 1])))
    with pytest.raises(MapFormatError, match='integer'):
        format_token_map(TokenMap('factory', np.array([[0.0, 1.0]])))
    with pytest.raises(UnknownScenarioError):
        format_token_map(TokenMap('kitchen', np.array([[0]])))


def test_tokens_to_occupancy_uses_each_scenarios_encoding():
    assert tokens_to_occupancy(np.array([[0, 1]]), 'factory').tolist() == [[0, 100]]
    assert tokens_to_occupancy(np.array([[0, 1]]), 'racetrack').tolist() == [[0, 100]]
    drone = tokens_to_occupancy(np.array([[0, 1, 2]]), get_scenario('drone'))
    assert drone.tolist() == [[0, 100, 50]]
    assert drone.dtype == np.int8


def test_occupancy_to_tokens_maps_low_obstacles_and_unknown():
    occupancy = np.array([[0, 50, 100, -1, 37]], dtype=np.int8)
    assert occupancy_to_tokens(occupancy, 'drone').tolist() == [[0, 2, 1, 1, 2]]
    # No low-obstacle token: in-between values and unknown are blocked.
    assert occupancy_to_tokens(occupancy, 'factory').tolist() == [[0, 1, 1, 1, 1]]
    assert occupancy_to_tokens(occupancy, 'racetrack').tolist() == [[0, 1, 1, 1, 1]]
    with pytest.raises(MapFormatError, match=r'cell \(row 0, col 1\) holds 101'):
        occupancy_to_tokens(np.array([[0, 101]]), 'factory')


def test_occupancy_round_trip_for_every_scenario():
    rng = np.random.default_rng(2)
    for name, spec in SCENARIOS.items():
        cells = rng.integers(0, spec.num_tokens, size=(6, 9))
        back = occupancy_to_tokens(tokens_to_occupancy(cells, name), name)
        np.testing.assert_array_equal(back, cells)


def test_common_encoding_compares_scenarios():
    assert to_common_encoding(np.array([[0, 1]]), 'factory').tolist() == [[0, 2]]
    assert to_common_encoding(np.array([[0, 1]]), 'racetrack').tolist() == [[0, 2]]
    common = to_common_encoding(np.array([[0, 1, 2]]), 'drone')
    assert common.tolist() == [[0, 2, 1]]
    assert common.dtype == np.uint8


@pytest.mark.parametrize('name', ['factory', 'racetrack', 'drone'])
def test_example_maps_load(name):
    spec = get_scenario(name)
    token_map = load_example_map(name)
    assert token_map.scenario == name
    assert token_map.cells.shape == spec.default_size
    # Every token of the scenario appears in its example.
    assert set(np.unique(token_map.cells).tolist()) == set(range(spec.num_tokens))
    assert Path(EXAMPLE_MAP_DIR / f'{name}.txt').is_file()


def test_load_example_map_unknown_scenario():
    with pytest.raises(UnknownScenarioError, match='known scenarios'):
        load_example_map('kitchen')
