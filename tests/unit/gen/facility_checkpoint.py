"""A generator trained (tiny budget, real `train` entry point) on a facility map that is not
the scenario's example: other layout, other size (20 x 28 cells instead of 32 x 32)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sessgan_core.token_map import read_token_map
from sessgan_gen.train_cli import main as train_main

FACILITY_HEIGHT, FACILITY_WIDTH = 20, 28

FACILITY_ROWS = [
    'WWWWWWWWWWWWWWWWWWWWWWWWWWWW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWWWWWWGGGGGGGGGWWWWWWWGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWWWWWWGGGGGGGGGWWWWWWWGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWWWWWWGGGGWGGGGWWWWWWWGGW',
    'WGGGGGGGGGGGGWGGGGGGGGGGGGGW',
    'WGGGGGGGGGGGGWGGGGGGGGGGGGGW',
    'WWWWWWGGGWWWWWWWWWWGGGWWWWWW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWGGWGGWGGWGGWGGWGGWGGWGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWGGWGGWGGWGGWGGWGGWGGWGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WGGWGGWGGWGGWGGWGGWGGWGGWGGW',
    'WGGGGGGGGGGGGGGGGGGGGGGGGGGW',
    'WWWWWWWWWWWWWWWWWWWWWWWWWWWW',
]


def train_facility_checkpoint(folder: Path) -> tuple[Path, np.ndarray]:
    """(checkpoint path, the token cells it learned), trained in ``folder``."""
    map_file = folder / 'facility.txt'
    map_file.write_text('# scenario: factory\n' + '\n'.join(FACILITY_ROWS) + '\n')
    output = folder / 'facility.pt'
    argv = ['--scenario', 'factory', '--map-file', str(map_file), '--iterations', '2',
            '--channels', '4', '--output', str(output), '--seed', '3', '--threads', '1',
            '--no-progress']
    assert train_main(argv) == 0
    return output, read_token_map(map_file, 'factory').cells
