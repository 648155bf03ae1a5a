"""Every map this project exports loads in Nav2's map_server as the map it is: checked cell by
cell, with its resolution and origin, against an independent transcription of map_server's
loading rules (tests/unit/core/nav2_map_loading.py; Nav2 itself is not installed here)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.map_server_io import export_environment, read_map_server, write_map_server
from sessgan_core.token_map import load_example_map, tokens_to_occupancy
from tests.unit.core.nav2_map_loading import nav2_load_map

pytestmark = pytest.mark.unit


@pytest.mark.parametrize('scenario', ['factory', 'drone', 'racetrack'])
def test_an_exported_environment_loads_cell_by_cell(tmp_path, scenario):
    occupancy = tokens_to_occupancy(load_example_map(scenario).cells, scenario)
    environment = Environment('e', scenario, occupancy, 0.5, Pose2D(0.25, 0.25),
                              Pose2D(0.75, 0.75), origin=(-12.35, 4.4))
    export_environment(tmp_path / 'map.yaml', environment)
    loaded = nav2_load_map(tmp_path / 'map.yaml')
    assert np.array_equal(loaded.data, environment.occupancy)  # drone: low obstacles stay 50
    assert loaded.resolution == 0.5
    assert loaded.origin == (-12.35, 4.4, 0.0)
    ours = read_map_server(tmp_path / 'map.yaml')
    assert np.array_equal(ours.occupancy, loaded.data) and ours.origin == loaded.origin


def test_unknown_cells_and_a_relative_image_path_load_from_another_directory(tmp_path,
                                                                              monkeypatch):
    occupancy = np.array([[0, 100, -1], [-1, 0, 100]], dtype=np.int8)
    (tmp_path / 'maps').mkdir()
    write_map_server(tmp_path / 'maps' / 'm.yaml', occupancy, 0.05, (1.0, -2.0, 0.25))
    monkeypatch.chdir(tmp_path)  # the image path is relative to the YAML, not to the cwd
    loaded = nav2_load_map(os.path.join('maps', 'm.yaml'))
    assert np.array_equal(loaded.data, occupancy)
    assert loaded.origin == (1.0, -2.0, 0.25)


def test_the_oracle_refuses_what_map_server_refuses(tmp_path):
    write_map_server(tmp_path / 'm.yaml', np.zeros((2, 2), dtype=np.int8), 0.5)
    text = (tmp_path / 'm.yaml').read_text()
    (tmp_path / 'no_negate.yaml').write_text(
        '\n'.join(line for line in text.splitlines() if not line.startswith('negate')))
    with pytest.raises(AssertionError, match='negate'):
        nav2_load_map(tmp_path / 'no_negate.yaml')
    (tmp_path / 'short_origin.yaml').write_text(text.replace('origin: [0.0, 0.0, 0.0]',
                                                             'origin: [0.0, 0.0]'))
    with pytest.raises(AssertionError, match='3 elements'):
        nav2_load_map(tmp_path / 'short_origin.yaml')


@pytest.mark.parametrize('mode', ['trinary', 'scale'])
def test_a_png_s_transparent_pixels_load_as_map_server_loads_them(tmp_path, mode):
    """A map drawn with transparent unknown space (RGBA): map_server averages the opacity in as
    a fourth channel in trinary mode (transparent white is grey: unknown) and makes every pixel
    that is not opaque unknown in scale mode. Read with the alpha ignored, the outside was
    floor, and the import kept it as the facility's."""
    from PIL import Image

    rgba = np.zeros((6, 8, 4), dtype=np.uint8)
    rgba[..., :3] = 254  # white floor
    rgba[..., 3] = 255
    rgba[1:5, 2] = (0, 0, 0, 255)  # a wall
    rgba[:, 6:] = (255, 255, 255, 0)  # transparent white: outside the mapped area
    rgba[0, 0] = (254, 254, 254, 128)  # half transparent
    Image.fromarray(rgba, mode='RGBA').save(tmp_path / 'map.png')
    (tmp_path / 'map.yaml').write_text(
        f'image: map.png\nmode: {mode}\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n'
        'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n')
    loaded = nav2_load_map(tmp_path / 'map.yaml')
    ours = read_map_server(tmp_path / 'map.yaml')
    assert np.array_equal(ours.occupancy, loaded.data)
    assert (ours.occupancy[:, 6:] == -1).all() and (ours.occupancy[:, :2] != -1).any()
