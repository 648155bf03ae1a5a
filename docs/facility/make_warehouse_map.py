"""Write warehouse.pgm + warehouse.yaml: a SLAM-style map_server map of a made-up 24 m x 16 m
warehouse (shelf rows, a pillar row, a loading bay), as map_saver writes one: 0.05 m/px,
free 254, walls 0, unknown 205 around the mapped area, free_thresh 0.196. Made here so the
README walkthrough needs no third-party map::

    python docs/facility/make_warehouse_map.py [folder]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

RESOLUTION = 0.05
FREE, WALL, UNKNOWN = 254, 0, 205


def warehouse() -> np.ndarray:
    """The image, top row first: a 480 x 320 px hall inside 60 px of unknown space."""
    def px(metres: float) -> int:
        return round(metres / RESOLUTION)

    image = np.full((px(16) + 120, px(24) + 120), UNKNOWN, dtype=np.uint8)
    top, left = 60, 60
    hall = image[top:top + px(16), left:left + px(24)]
    hall[:] = WALL
    hall[px(0.3):-px(0.3), px(0.3):-px(0.3)] = FREE  # 0.3 m outer walls
    for row in range(3):  # shelf rows: 12 m x 1 m, 3 m apart, a 2 m gap in the middle
        y = px(3.0 + 3.5 * row)
        hall[y:y + px(1.0), px(4.0):px(10.0)] = WALL
        hall[y:y + px(1.0), px(12.0):px(18.0)] = WALL
    for x in np.arange(3.0, 22.0, 4.0):  # a row of 0.5 m pillars along the top
        hall[px(1.2):px(1.7), px(x):px(x + 0.5)] = WALL
    hall[px(12.5):px(16) - px(0.3), px(20.0):px(20.3)] = WALL  # the loading bay's side wall
    hall[-px(0.3):, px(21.0):px(23.0)] = FREE  # its door
    image[top + px(16):top + px(16) + px(0.6), left + px(21.0):left + px(23.0)] = FREE  # apron
    return image


def main(argv: list[str]) -> int:
    folder = Path(argv[0]) if argv else Path('.')
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(warehouse(), mode='L').save(folder / 'warehouse.pgm')
    (folder / 'warehouse.yaml').write_text(
        'image: warehouse.pgm\nmode: trinary\nresolution: 0.05\norigin: [-7.5, -4.0, 0.0]\n'
        'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n')
    print(f'{folder / "warehouse.yaml"} and {folder / "warehouse.pgm"}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
