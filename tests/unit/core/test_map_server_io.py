"""Tests of map_server PGM + YAML import and export."""

import math

import numpy as np
import pytest
import yaml

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.errors import MapFormatError
from sessgan_core.map_server_io import (
    export_environment,
    export_token_map,
    import_map_server,
    read_map_server,
    read_pgm,
    resample_tokens,
    specks,
    write_map_server,
)
from sessgan_core.token_map import TokenMap

pytestmark = pytest.mark.unit


def write_pgm_p5(path, pixels, maxval=255):
    pixels = np.asarray(pixels)
    header = f'P5\n# a comment\n{pixels.shape[1]} {pixels.shape[0]}\n{maxval}\n'.encode()
    dtype = np.uint8 if maxval < 256 else np.dtype('>u2')
    path.write_bytes(header + pixels.astype(dtype).tobytes())


def write_yaml(path, **keys):
    document = {'image': 'map.pgm', 'resolution': 0.05, 'origin': [-1.0, -2.0, 0.5],
                'negate': 0, 'occupied_thresh': 0.65, 'free_thresh': 0.196}
    document.update(keys)
    document = {key: value for key, value in document.items() if value is not None}
    path.write_text(yaml.safe_dump(document))
    return path


def test_round_trip_keeps_values_resolution_and_origin(tmp_path):
    occupancy = np.array([[0, 50, 100], [100, 0, 0]], dtype=np.int8)
    image = write_map_server(tmp_path / 'm.yaml', occupancy, 0.5, (1.5, -2.0, 0.25))
    assert image == tmp_path / 'm.pgm'
    loaded = read_map_server(tmp_path / 'm.yaml')
    np.testing.assert_array_equal(loaded.occupancy, occupancy)
    assert loaded.occupancy.dtype == np.int8
    assert loaded.resolution == 0.5
    assert loaded.origin == (1.5, -2.0, 0.25)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['m.pgm', 'm.yaml']


def test_written_pixels_and_yaml_follow_map_server(tmp_path):
    occupancy = np.array([[0, 50], [100, 0]], dtype=np.int8)
    write_map_server(tmp_path / 'm.yaml', occupancy, 0.5)
    pixels, maxval = read_pgm(tmp_path / 'm.pgm')
    assert maxval == 255
    # Image rows are top first: OccupancyGrid row 1 is the image's first row.
    assert pixels.tolist() == [[0, 254], [254, 147]]
    document = yaml.safe_load((tmp_path / 'm.yaml').read_text())
    # map_saver's thresholds (since mid-2025).
    assert document == {'image': 'm.pgm', 'mode': 'scale', 'resolution': 0.5,
                        'origin': [0.0, 0.0, 0.0], 'negate': 0,
                        'occupied_thresh': 0.65, 'free_thresh': 0.196}
    # What Nav2's scale mode computes for the grey of a low obstacle.
    occ = 1.0 - 147 / 255.0
    assert round((occ - 0.196) / (0.65 - 0.196) * 100.0) == 50


def test_maps_without_low_obstacles_are_trinary_and_unknown_is_grey(tmp_path):
    occupancy = np.array([[0, -1, 100]], dtype=np.int8)
    write_map_server(tmp_path / 'm.yaml', occupancy, 1.0)
    assert yaml.safe_load((tmp_path / 'm.yaml').read_text())['mode'] == 'trinary'
    assert read_pgm(tmp_path / 'm.pgm')[0].tolist() == [[254, 127, 0]]
    np.testing.assert_array_equal(read_map_server(tmp_path / 'm.yaml').occupancy, occupancy)


def test_every_intermediate_value_survives_scale_mode(tmp_path):
    values = np.arange(0, 101, dtype=np.int8).reshape(1, -1)
    write_map_server(tmp_path / 'm.yaml', values, 0.1)
    np.testing.assert_array_equal(read_map_server(tmp_path / 'm.yaml').occupancy, values)


def test_trinary_thresholds_and_row_order(tmp_path):
    # 255 white: occ 0, free; 0 and 50 dark: occ 1 and 0.80, occupied; 205: occ 0.19608,
    # just above free_thresh 0.196, unknown.
    write_pgm_p5(tmp_path / 'map.pgm', [[255, 0], [205, 50]])
    write_yaml(tmp_path / 'map.yaml')
    loaded = read_map_server(tmp_path / 'map.yaml')
    assert loaded.occupancy.tolist() == [[-1, 100], [0, 100]]
    assert loaded.resolution == 0.05
    assert loaded.origin == (-1.0, -2.0, 0.5)


def test_negate_inverts_the_shade(tmp_path):
    write_pgm_p5(tmp_path / 'map.pgm', [[255, 0]])
    write_yaml(tmp_path / 'map.yaml', negate=1)
    assert read_map_server(tmp_path / 'map.yaml').occupancy.tolist() == [[100, 0]]
    write_yaml(tmp_path / 'map.yaml', negate=True)
    assert read_map_server(tmp_path / 'map.yaml').occupancy.tolist() == [[100, 0]]


def test_scale_and_raw_modes(tmp_path):
    write_pgm_p5(tmp_path / 'map.pgm', [[255, 0, 128, 30, 200]])
    write_yaml(tmp_path / 'map.yaml', mode='scale', free_thresh=0.25, occupied_thresh=0.65)
    expected_mid = round((1 - 128 / 255 - 0.25) / 0.4 * 100)
    assert read_map_server(tmp_path / 'map.yaml').occupancy.tolist() == [
        [0, 100, expected_mid, 100, 0]]
    write_yaml(tmp_path / 'map.yaml', mode='raw')
    assert read_map_server(tmp_path / 'map.yaml').occupancy.tolist() == [[-1, 0, -1, 30, -1]]


def test_mode_is_the_only_key_with_a_default(tmp_path):
    """As map_server's loadMapYaml: mode defaults to trinary; negate and both thresholds are
    required (a missing free_thresh is not taken as some default)."""
    write_pgm_p5(tmp_path / 'map.pgm', [[254, 0]])
    write_yaml(tmp_path / 'map.yaml', mode=None, origin=[3, 4, 0])
    loaded = read_map_server(tmp_path / 'map.yaml')
    assert loaded.occupancy.tolist() == [[0, 100]]
    assert loaded.origin == (3.0, 4.0, 0.0)
    for key in ('negate', 'occupied_thresh', 'free_thresh'):
        write_yaml(tmp_path / 'map.yaml', **{key: None})
        with pytest.raises(MapFormatError, match=f"required key '{key}' is missing"):
            read_map_server(tmp_path / 'map.yaml')


@pytest.mark.parametrize('origin', [[3, 4], [3, 4, 0, 0]])
def test_an_origin_of_other_than_3_elements_is_refused_as_map_server_does(tmp_path, origin):
    """nav2_map_server's loadMapYaml: "value of the 'origin' tag should have 3 elements"."""
    write_pgm_p5(tmp_path / 'map.pgm', [[254, 0]])
    path = write_yaml(tmp_path / 'map.yaml', origin=origin)
    with pytest.raises(MapFormatError) as raised:
        read_map_server(path)
    assert str(path) in str(raised.value) and "'origin'" in str(raised.value)
    assert f'got {len(origin)} elements' in str(raised.value)
    # Our writer takes (x, y) from Python but writes the 3 elements map_server needs.
    write_map_server(tmp_path / 'w.yaml', np.zeros((1, 1), dtype=np.int8), 0.5, (3.0, 4.0))
    assert yaml.safe_load((tmp_path / 'w.yaml').read_text())['origin'] == [3.0, 4.0, 0.0]


def test_specks_are_small_8_connected_regions_of_one_value_inside_free_floor():
    grid = np.zeros((10, 14), dtype=np.int8)
    grid[1, 1] = -1                            # a lone pixel: a speck
    grid[5, 1] = grid[6, 2] = grid[7, 1] = -1  # a diagonal chain: one speck of 3 px
    grid[3:5, 5:7] = -1                        # 4 px inside free floor: a speck under 5
    grid[1, 10], grid[2, 11] = -1, 100         # a wall at its corner: not a speck
    grid[0, 6] = -1                            # on the edge: not a speck
    grid[8, 5], grid[8, 6] = -1, 50            # next to a low obstacle: not a speck
    grid[5, 10], grid[5, 11] = -1, 100         # next to an occupied speck: not a speck
    mask, count = specks(grid, -1, 5)
    expected = np.zeros(grid.shape, dtype=bool)
    expected[1, 1] = expected[5, 1] = expected[6, 2] = expected[7, 1] = True
    expected[3:5, 5:7] = True
    assert count == 3 and np.array_equal(mask, expected)
    # Fewer pixels than max_pixels only: the chain of 3 and the square of 4 are too big for 3.
    mask, count = specks(grid, -1, 3)
    assert count == 1 and mask.sum() == 1 and mask[1, 1]
    assert specks(np.zeros((3, 3), dtype=np.int8), -1, 5)[1] == 0
    assert specks(np.full((3, 3), -1, dtype=np.int8), -1, 50)[1] == 0
    # Occupied specks by the same rule: the walls above touch unknown, a lone one does not.
    grid[8, 12] = 100
    mask, count = specks(grid, 100, 5)
    assert count == 1 and mask.sum() == 1 and mask[8, 12]


def test_p2_and_16_bit_and_absolute_image_path(tmp_path):
    folder = tmp_path / 'images'
    folder.mkdir()
    (folder / 'ascii.pgm').write_text('P2\n# comment\n3 1\n15\n15 0 # trailing\n 7\n')
    write_yaml(tmp_path / 'map.yaml', image=str(folder / 'ascii.pgm'), mode='trinary')
    assert read_map_server(tmp_path / 'map.yaml').occupancy.tolist() == [[0, 100, -1]]
    write_pgm_p5(tmp_path / 'map.pgm', [[65535, 0]], maxval=65535)
    write_yaml(tmp_path / 'deep.yaml')
    assert read_map_server(tmp_path / 'deep.yaml').occupancy.tolist() == [[0, 100]]


@pytest.mark.parametrize('keys, message', [
    ({'image': None}, "required key 'image' is missing"),
    ({'resolution': None}, "required key 'resolution' is missing"),
    ({'origin': None}, "required key 'origin' is missing"),
    ({'resolution': -0.05}, "'resolution' must be a positive number"),
    ({'resolution': 0}, "'resolution' must be a positive number"),
    ({'resolution': 'fine'}, "'resolution' must be a finite number"),
    ({'origin': [1.0]}, "'origin' must be a list"),
    ({'origin': 'zero'}, "'origin' must be a list"),
    ({'negate': 2}, "'negate' must be 0, 1"),
    ({'free_thresh': 0.7}, 'free_thresh < occupied_thresh'),
    ({'mode': 'fancy'}, "'mode' must be one of"),
    ({'image': 'map.png'}, 'does not exist'),
    ({'image': 'other.pgm'}, 'does not exist'),
])
def test_malformed_yaml_is_reported(tmp_path, keys, message):
    write_pgm_p5(tmp_path / 'map.pgm', [[255]])
    write_yaml(tmp_path / 'map.yaml', **keys)
    with pytest.raises(MapFormatError, match=message):
        read_map_server(tmp_path / 'map.yaml')


def test_unreadable_yaml_documents(tmp_path):
    with pytest.raises(MapFormatError, match='does not exist'):
        read_map_server(tmp_path / 'nothing.yaml')
    (tmp_path / 'a.yaml').write_text('image: [unclosed\n')
    with pytest.raises(MapFormatError, match='invalid YAML'):
        read_map_server(tmp_path / 'a.yaml')
    (tmp_path / 'b.yaml').write_text('- just\n- a list\n')
    with pytest.raises(MapFormatError, match='expected a mapping'):
        read_map_server(tmp_path / 'b.yaml')


@pytest.mark.parametrize('content, message', [
    (b'P6\n1 1\n255\n\x00\x00\x00', 'not a PGM image'),
    (b'GIF89a', 'not a PGM image'),
    (b'P5\n4 4\n255\n' + bytes(10), 'need 16 bytes of data, found 10'),
    (b'P5\n4 4\n255', 'no pixel data'),
    (b'P5\n4', 'expected the height, found end of file'),
    (b'P5\nfour 4\n255\n', "expected the width, found b'f'"),
    (b'P5\n0 4\n255\n', 'outside 1..'),
    (b'P5\n1 1\n0\n\x00', 'maxval 0'),
    (b'P2\n2 2\n255\n1 2 3\n', 'found 3'),
    (b'P2\n2 1\n10\n1 20\n', 'exceeds the PGM maxval 10'),
])
def test_malformed_pgm_is_reported(tmp_path, content, message):
    (tmp_path / 'map.pgm').write_bytes(content)
    write_yaml(tmp_path / 'map.yaml')
    with pytest.raises(MapFormatError, match=message):
        read_map_server(tmp_path / 'map.yaml')


def test_write_rejects_bad_input(tmp_path):
    good = np.zeros((2, 2), dtype=np.int8)
    with pytest.raises(MapFormatError, match='resolution'):
        write_map_server(tmp_path / 'm.yaml', good, -1.0)
    with pytest.raises(MapFormatError, match='origin'):
        write_map_server(tmp_path / 'm.yaml', good, 1.0, (math.nan, 0.0))
    with pytest.raises(MapFormatError, match='holds 120'):
        write_map_server(tmp_path / 'm.yaml', np.array([[0, 120]]), 1.0)
    with pytest.raises(MapFormatError, match='cannot represent both'):
        write_map_server(tmp_path / 'm.yaml', np.array([[-1, 50]]), 1.0)
    assert list(tmp_path.iterdir()) == []


def test_resample_keeps_thin_structures_by_hierarchy():
    cells = np.zeros((8, 8), dtype=np.int64)
    cells[:, 3] = 1  # a one-cell wall
    down = resample_tokens(cells, 'factory', (4, 4))
    assert down.tolist() == [[0, 1, 0, 0]] * 4
    # Racetrack: the track (0) outranks out-of-bounds (1), so a thin track survives.
    track = np.ones((6, 6), dtype=np.int64)
    track[2, :] = 0
    assert resample_tokens(track, 'racetrack', (3, 3)).tolist() == [[1, 1, 1], [0, 0, 0],
                                                                     [1, 1, 1]]
    # Drone hierarchy G < O < W.
    drone = np.array([[0, 2], [2, 1]])
    assert resample_tokens(drone, 'drone', (1, 1)).tolist() == [[1]]
    assert resample_tokens(drone[:1], 'drone', (1, 1)).tolist() == [[2]]
    # Non-integer ratios: a cell overlapping two inputs sees both.
    assert resample_tokens(np.array([[0, 0, 1]]), 'factory', (1, 2)).tolist() == [[0, 1]]
    up = resample_tokens(np.array([[0, 1]]), 'factory', (2, 4))
    assert up.tolist() == [[0, 0, 1, 1]] * 2
    with pytest.raises(MapFormatError, match='outside'):
        resample_tokens(cells, 'factory', (0, 4))


def test_import_thresholds_then_resamples(tmp_path):
    pixels = np.full((8, 8), 254)
    pixels[0, :] = 0       # wall along the top of the image
    pixels[5, 5] = 205     # unknown -> blocked
    write_pgm_p5(tmp_path / 'map.pgm', pixels)
    write_yaml(tmp_path / 'map.yaml')
    full = import_map_server(tmp_path / 'map.yaml', 'factory')
    assert full.scenario == 'factory'
    assert full.cells.shape == (8, 8)
    assert full.cells[7].tolist() == [1] * 8  # the image's top row is the grid's last row
    assert full.cells[2, 5] == 1
    small = import_map_server(tmp_path / 'map.yaml', 'factory', size=(4, 4))
    assert small.cells.tolist() == [[0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0], [1, 1, 1, 1]]


def test_import_drone_low_obstacles(tmp_path):
    occupancy = np.array([[0, 50, 100]], dtype=np.int8)
    write_map_server(tmp_path / 'm.yaml', occupancy, 0.5)
    assert import_map_server(tmp_path / 'm.yaml', 'drone').cells.tolist() == [[0, 2, 1]]
    assert import_map_server(tmp_path / 'm.yaml', 'factory').cells.tolist() == [[0, 1, 1]]


def test_export_environment_and_token_map(tmp_path):
    occupancy = np.array([[0, 100], [50, 0]], dtype=np.int8)
    environment = Environment('e1', 'drone', occupancy, 0.5, Pose2D(0.25, 0.25),
                              Pose2D(0.75, 0.75), origin=(2.0, 3.0))
    export_environment(tmp_path / 'env.yaml', environment)
    loaded = read_map_server(tmp_path / 'env.yaml')
    np.testing.assert_array_equal(loaded.occupancy, occupancy)
    assert loaded.origin == (2.0, 3.0, 0.0)
    export_token_map(tmp_path / 'tm.yaml', TokenMap('racetrack', np.array([[0, 1]])))
    loaded = read_map_server(tmp_path / 'tm.yaml')
    assert loaded.occupancy.tolist() == [[0, 100]]
    assert loaded.resolution == 1.0


def write_negated_facility(directory, origin=(-3.2, 1.5, 0.0)):
    """A 160x120-pixel map_server map at 0.05 m/px (8 x 6 m) saved with ``negate: 1`` (white is
    occupied): a 0.5 m thick border wall, a 1 x 1 m block, a grey (unknown) patch; trinary
    mode, a non-zero origin. Returns (yaml path, the factory token map it should become at
    0.5 m per cell: 12 rows x 16 columns, row 0 at the bottom)."""
    pixels = np.zeros((120, 160), dtype=np.uint8)  # negate: black is free
    pixels[:10, :] = pixels[-10:, :] = pixels[:, :10] = pixels[:, -10:] = 255  # 0.5 m walls
    pixels[30:50, 60:80] = 255  # a 1 x 1 m block, image rows 30..49 (top first)
    pixels[80:90, 120:130] = 128  # a grey 0.5 m square: unknown, so blocked for a robot
    write_pgm_p5(directory / 'facility.pgm', pixels)
    yaml_path = write_yaml(directory / 'facility.yaml', image='facility.pgm', resolution=0.05,
                           origin=list(origin), negate=1, mode='trinary', occupied_thresh=0.65,
                           free_thresh=0.25)
    expected = np.zeros((12, 16), dtype=np.int64)
    expected[0, :] = expected[-1, :] = expected[:, 0] = expected[:, -1] = 1
    expected[12 - 5:12 - 3, 6:8] = 1  # image rows 30..49 = cell rows 3..4 from the top
    expected[12 - 9, 12] = 1  # image rows 80..89 = cell row 8 from the top
    return yaml_path, expected


def test_map_server_map_imports_at_the_scenarios_cell_size(tmp_path):
    from sessgan_core.map_server_io import cells_at_cell_size, import_map_server_for_scenario

    yaml_path, expected = write_negated_facility(tmp_path)
    loaded = read_map_server(yaml_path)
    assert loaded.origin == (-3.2, 1.5, 0.0)
    assert loaded.occupancy[0, 0] == 100 and loaded.occupancy[60, 40] == 0  # negate applied
    assert loaded.occupancy[120 - 85, 125] == -1  # trinary: grey between thresholds
    assert cells_at_cell_size(loaded.occupancy.shape, 0.05, 0.5) == (12, 16)
    token_map = import_map_server_for_scenario(yaml_path, 'factory')
    assert token_map.scenario == 'factory'
    np.testing.assert_array_equal(token_map.cells, expected)


def test_a_map_too_large_for_the_cell_size_is_refused(tmp_path):
    from sessgan_core.map_server_io import cells_at_cell_size, import_map_server_for_scenario

    write_pgm_p5(tmp_path / 'map.pgm', np.zeros((4, 4), dtype=np.uint8))
    write_yaml(tmp_path / 'map.yaml', resolution=1000.0)
    with pytest.raises(MapFormatError, match='more than 4096 per side'):
        import_map_server_for_scenario(tmp_path / 'map.yaml', 'factory')
    assert cells_at_cell_size((3, 1), 0.01, 0.5) == (1, 1)  # never zero cells


def test_written_images_open_in_pillow_and_a_maxval_100_image_keeps_exact_shades(tmp_path):
    from PIL import Image

    write_map_server(tmp_path / 'm.yaml', np.array([[0, 50], [100, 0]], dtype=np.int8), 0.5)
    with Image.open(tmp_path / 'm.pgm') as image:
        assert image.format == 'PPM' and image.mode == 'L'
        assert np.asarray(image).tolist() == [[0, 254], [254, 147]]
    # value 35 of maxval 100 is occ 0.65 exactly: unknown for map_server (occ must exceed
    # occupied_thresh); a reader that rescales to 8 bits would make it occupied.
    (tmp_path / 'h.pgm').write_bytes(b'P5\n3 1\n100\n' + bytes([35, 100, 0]))
    (tmp_path / 'h.yaml').write_text('image: h.pgm\nresolution: 1.0\norigin: [0, 0, 0]\n'
                                      'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n')
    assert read_pgm(tmp_path / 'h.pgm')[0].tolist() == [[35, 100, 0]]
    assert read_map_server(tmp_path / 'h.yaml').occupancy.tolist() == [[-1, 0, 100]]
