"""Importing a facility's own map for training: a SLAM map's unknown margin is cropped away,
a map that is mostly wall or unknown is warned about, PNG images load, and bad inputs (an
empty YAML, a map too small or too large to learn) say what is wrong."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from PIL import Image

from sessgan_core.errors import MapFormatError
from sessgan_core.map_server_io import import_facility_map, read_map_server
from sessgan_gen.model import pyramid_scale_shapes
from sessgan_gen.training import check_training_map, long_training_warning

pytestmark = pytest.mark.unit

FREE, WALL, UNKNOWN = 254, 0, 205  # map_saver's shades


def slam_map(folder, name='slam', room=(120, 160), image=(240, 300), at=(50, 70),
             origin=(-5.0, -3.0, 0.0), suffix='.pgm', free_thresh=0.196):
    """A SLAM-like map: a free room with 2-pixel walls at image row/column ``at`` (top
    first), surrounded by unknown space; map_saver's YAML (free_thresh 0.196, so its unknown
    grey 205 reads as unknown). Returns the YAML path."""
    pixels = np.full(image, UNKNOWN, dtype=np.uint8)
    top, left = at
    height, width = room
    pixels[top:top + height, left:left + width] = WALL
    pixels[top + 2:top + height - 2, left + 2:left + width - 2] = FREE
    Image.fromarray(pixels, mode='L').save(folder / f'{name}{suffix}')
    document = {'image': f'{name}{suffix}', 'resolution': 0.05, 'origin': list(origin),
                'negate': 0, 'occupied_thresh': 0.65, 'free_thresh': free_thresh}
    (folder / f'{name}.yaml').write_text(yaml.safe_dump(document))
    return folder / f'{name}.yaml'


def test_a_slam_map_is_cropped_to_its_known_region(tmp_path):
    imported = import_facility_map(slam_map(tmp_path), 'factory')
    # 160 x 120 known pixels of 0.05 m: 8 m x 6 m, 16 x 12 cells of 0.5 m.
    assert imported.token_map.cells.shape == (12, 16)
    cells = imported.token_map.cells
    assert cells[0].tolist() == [1] * 16 and cells[:, 0].tolist() == [1] * 12
    assert (cells[1:-1, 1:-1] == 0).all()  # the room's floor, all of it
    assert imported.free_fraction == pytest.approx(10 * 14 / (12 * 16))
    assert imported.known_fraction == 1.0 and imported.warnings() == []
    # OccupancyGrid rows count from the bottom: the room starts 240 - 50 - 120 = 70 rows up.
    assert imported.known_box == (70, 190, 70, 230)
    assert imported.origin == pytest.approx((-5.0 + 70 * 0.05, -3.0 + 70 * 0.05, 0.0))
    # The YAML says the decimal: -2.3 + 70 * 0.05 alone is 1.2000000000000002.
    moved = import_facility_map(slam_map(tmp_path, origin=(-2.3, -2.3, 0.0)), 'factory')
    assert moved.origin == (1.2, 1.2, 0.0)
    assert 'cropped to its known region of 160x120 px' in imported.summary()


def test_a_map_of_no_whole_cells_is_filled_up_with_wall_not_stretched(tmp_path):
    """9.75 m x 6 m of map (195 x 120 px) makes 20 x 12 cells of 0.5 m: the last column's
    missing 0.25 m is wall, and a wall 7.0-7.5 m from the map's left edge lies in cell 14
    alone (stretched to 10 m, it would reach into cell 13 as well)."""
    pixels = np.full((120, 195), FREE, dtype=np.uint8)
    pixels[:, 140:150] = WALL
    Image.fromarray(pixels, mode='L').save(tmp_path / 'hall.pgm')
    document = {'image': 'hall.pgm', 'resolution': 0.05, 'origin': [1.0, 2.0, 0.0],
                'negate': 0, 'occupied_thresh': 0.65, 'free_thresh': 0.196}
    (tmp_path / 'hall.yaml').write_text(yaml.safe_dump(document))
    imported = import_facility_map(tmp_path / 'hall.yaml', 'factory')
    cells = imported.token_map.cells
    assert cells.shape == (12, 20)
    walls = sorted({int(col) for col in np.flatnonzero((cells == 1).all(axis=0))})
    assert walls == [14, 19]
    assert (cells[:, :14] == 0).all() and (cells[:, 15:19] == 0).all()
    assert imported.origin == (1.0, 2.0, 0.0)


def test_map_savers_unknown_grey_stays_unknown_under_its_old_free_thresh(tmp_path):
    """Nav2's map_saver wrote free_thresh 0.25 until mid-2025, under which its unknown grey
    205 reads as free in map_server: the import still crops to the known region and says so."""
    exact = import_facility_map(slam_map(tmp_path), 'factory')
    old = import_facility_map(slam_map(tmp_path, 'old', free_thresh=0.25), 'factory')
    assert np.array_equal(old.token_map.cells, exact.token_map.cells)
    assert (old.known_box, old.origin) == (exact.known_box, exact.origin)
    assert old.saver_unknown == 240 * 300 - 120 * 160 and exact.saver_unknown == 0
    assert 'grey 205' in ' '.join(old.warnings()) and exact.warnings() == []
    # map_server itself reads it as free, and this reader is map_server's.
    assert (read_map_server(tmp_path / 'old.yaml').occupancy == 0).mean() > 0.9


def test_specks_of_unknown_inside_free_floor_are_floor_not_pillars(tmp_path):
    """A SLAM map's single unobserved pixels inside free floor would each become a whole
    0.5 m wall cell: they are taken as floor and counted. Unknown of a quarter cell or more
    (25 px at 0.05 m/px), or touching a wall, still counts as wall."""
    clean = import_facility_map(slam_map(tmp_path, 'clean'), 'factory')
    path = slam_map(tmp_path, 'specks')
    pixels = np.asarray(Image.open(tmp_path / 'specks.pgm')).copy()
    # The room's cells start at image row 50 and column 70, 10 px each; (a, b) counts cells
    # from the top left.
    for a in (2, 4, 6, 8):
        for b in range(1, 11):
            pixels[50 + 10 * a + 5, 70 + 10 * b + 5] = UNKNOWN
    pixels[82:87, 192:197] = UNKNOWN  # 25 px of cell (3, 12): not a speck
    pixels[105, 199], pixels[105, 200] = WALL, UNKNOWN  # a table leg ends cell (5, 12)
    Image.fromarray(pixels, mode='L').save(tmp_path / 'specks.pgm')
    imported = import_facility_map(path, 'factory')
    assert (imported.floor_specks, imported.floor_speck_pixels) == (40, 40)
    expected = clean.token_map.cells.copy()
    for a, b in ((3, 12), (5, 12), (5, 13)):  # token rows count from the bottom
        expected[11 - a, b] = 1
    assert np.array_equal(imported.token_map.cells, expected)
    assert imported.free_fraction == pytest.approx((10 * 14 - 3) / (12 * 16))
    # known_fraction is of the map as learned: the specks are known floor now.
    assert imported.known_fraction == pytest.approx(1 - 26 / (120 * 160))
    assert '; 40 specks of unknown inside free floor (40 px in all' in imported.summary()
    assert imported.warnings() == [] and 'specks' not in clean.summary()


def test_a_rotated_origin_moves_along_the_maps_axes(tmp_path):
    imported = import_facility_map(slam_map(tmp_path, origin=(1.0, 2.0, np.pi / 2)), 'factory')
    x, y, yaw = imported.origin
    # Along the map's x axis (pointing up in the world) 3.5 m, along its y axis (pointing -x)
    # 3.5 m.
    assert (x, y, yaw) == pytest.approx((1.0 - 3.5, 2.0 + 3.5, np.pi / 2))


def test_little_free_space_and_much_unknown_inside_are_warned_about(tmp_path):
    # A room that is almost all wall: its floor is a 6-pixel strip.
    walls = slam_map(tmp_path, 'walls', room=(120, 160))
    pixels = np.asarray(Image.open(tmp_path / 'walls.pgm')).copy()
    pixels[52:168, 72:228] = WALL
    pixels[100:106, 72:228] = FREE
    Image.fromarray(pixels, mode='L').save(tmp_path / 'walls.pgm')
    warnings = import_facility_map(walls, 'factory').warnings()
    assert len(warnings) == 1 and 'free floor' in warnings[0]
    # A room whose inner half was never mapped.
    patchy = slam_map(tmp_path, 'patchy')
    pixels = np.asarray(Image.open(tmp_path / 'patchy.pgm')).copy()
    pixels[52:168, 72:150] = UNKNOWN
    Image.fromarray(pixels, mode='L').save(tmp_path / 'patchy.pgm')
    assert any('unknown and counts as wall' in w
               for w in import_facility_map(patchy, 'factory').warnings())


def test_a_map_with_nothing_known_is_refused(tmp_path):
    path = slam_map(tmp_path, room=(0, 0))
    with pytest.raises(MapFormatError, match='every cell of the map is unknown'):
        import_facility_map(path, 'factory')


def test_specks_of_wall_inside_free_floor_are_floor_and_larger_objects_stay(tmp_path):
    """Lidar noise (single occupied pixels inside free floor) would each become a whole 0.5 m
    pillar: specks under a 16th of a cell (6.25 px at 0.05 m/px) are taken as floor and
    counted; a 3 x 3 px object (9 px) and a speck touching a wall stay wall."""
    clean = import_facility_map(slam_map(tmp_path, 'clean'), 'factory')
    path = slam_map(tmp_path, 'noise')
    pixels = np.asarray(Image.open(tmp_path / 'noise.pgm')).copy()
    for b in range(1, 11):
        pixels[50 + 10 * 4 + 5, 70 + 10 * b + 5] = WALL  # one pixel in each of cells (4, b)
    pixels[75, 75:77] = pixels[76, 76] = WALL  # 3 px, 8-connected: one speck
    pixels[82:85, 192:195] = WALL  # 9 px in cell (3, 12): an object
    pixels[52, 100] = WALL  # touches the top wall (rows 50-51) at a corner: wall
    Image.fromarray(pixels, mode='L').save(tmp_path / 'noise.pgm')
    imported = import_facility_map(path, 'factory')
    assert (imported.wall_specks, imported.wall_speck_pixels) == (11, 13)
    expected = clean.token_map.cells.copy()
    expected[11 - 3, 12] = 1  # token rows count from the bottom
    assert np.array_equal(imported.token_map.cells, expected)
    assert '11 specks of occupied pixels inside free floor (13 px in all' in imported.summary()


def two_rooms(folder, door_rows, name='rooms'):
    """Two 4 m x 3.5 m rooms side by side, a 2-pixel wall between them at columns 80-81 with
    a door at image rows ``door_rows``, 0.05 m/px; returns the YAML path."""
    pixels = np.full((74, 164), WALL, dtype=np.uint8)
    pixels[2:72, 2:80] = FREE
    pixels[2:72, 82:162] = FREE
    pixels[door_rows[0]:door_rows[1], 80:82] = FREE
    Image.fromarray(pixels, mode='L').save(folder / f'{name}.pgm')
    (folder / f'{name}.yaml').write_text(yaml.safe_dump({
        'image': f'{name}.pgm', 'resolution': 0.05, 'origin': [0.0, 0.0, 0.0], 'negate': 0,
        'occupied_thresh': 0.65, 'free_thresh': 0.196}))
    return folder / f'{name}.yaml'


def test_a_door_that_resampling_closes_is_warned_about(tmp_path):
    """A 1.1 m door (22 px) across the 0.5 m cells' edges keeps one whole cell, 0.5 m, too
    narrow for the 0.2 m robot's 0.6 m route: the second room is sealed off in the learned
    map, and train says so. A 2 m door stays open: no warning."""
    narrow = import_facility_map(two_rooms(tmp_path, (25, 47), 'narrow'), 'factory')
    assert narrow.reachable[0] == 1.0 and narrow.reachable[1] < 0.7, narrow.reachable
    assert any('closed openings' in warning for warning in narrow.warnings())
    wide = import_facility_map(two_rooms(tmp_path, (20, 60), 'wide'), 'factory')
    assert wide.reachable == (1.0, 1.0) and wide.warnings() == []


def test_png_images_load_like_their_pgm(tmp_path):
    pgm = read_map_server(slam_map(tmp_path, 'as_pgm'))
    png = read_map_server(slam_map(tmp_path, 'as_png', suffix='.png'))
    np.testing.assert_array_equal(png.occupancy, pgm.occupancy)
    # A colour PNG: the shade is the mean of the channels (map_server's rule).
    Image.fromarray(np.array([[[254, 254, 254], [0, 0, 0], [200, 210, 205]]], dtype=np.uint8),
                    mode='RGB').save(tmp_path / 'colour.png')
    (tmp_path / 'colour.yaml').write_text(yaml.safe_dump({
        'image': 'colour.png', 'resolution': 0.05, 'origin': [0, 0, 0],
        'negate': 0, 'free_thresh': 0.196, 'occupied_thresh': 0.65}))
    assert read_map_server(tmp_path / 'colour.yaml').occupancy.tolist() == [[0, 100, -1]]
    (tmp_path / 'broken.png').write_bytes(b'\x89PNG not really')
    (tmp_path / 'broken.yaml').write_text(yaml.safe_dump({
        'image': 'broken.png', 'resolution': 0.05, 'origin': [0, 0, 0], 'negate': 0,
        'free_thresh': 0.196, 'occupied_thresh': 0.65}))
    with pytest.raises(MapFormatError, match='cannot read map image'):
        read_map_server(tmp_path / 'broken.yaml')


def test_an_empty_yaml_says_it_is_empty(tmp_path):
    (tmp_path / 'empty.yaml').write_text('')
    with pytest.raises(MapFormatError, match='the file is empty'):
        read_map_server(tmp_path / 'empty.yaml')


def test_the_image_given_for_the_yaml_says_so(tmp_path):
    Image.fromarray(np.full((4, 4), FREE, dtype=np.uint8), mode='L').save(tmp_path / 'map.png')
    with pytest.raises(MapFormatError, match='is no map YAML .* give the .yaml'):
        read_map_server(tmp_path / 'map.png')


def test_a_map_too_small_to_learn_is_named():
    check_training_map(np.zeros((8, 12)))
    with pytest.raises(ValueError, match='the map is 1x1 cells .* at least 8 cells per side'):
        check_training_map(np.zeros((1, 1)))


def test_a_long_training_is_warned_about_and_a_short_one_is_not():
    huge = pyramid_scale_shapes(600, 600)  # a 6,000 x 6,000 image at 0.05 m
    warning = long_training_warning(huge, 1000, 32)
    assert '600x600-cell map' in warning and ' h on one CPU thread' in warning
    assert 'memory' in warning
    assert long_training_warning(pyramid_scale_shapes(32, 32), 1000, 32) == ''
    assert long_training_warning(huge, 2, 4) == ''
