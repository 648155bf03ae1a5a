"""An independent transcription of how Nav2's map_server loads a map (nav2_map_server
map_io.cpp, ``loadMapYaml`` and ``loadMapFromFile``), used as the oracle that this project's
exports load in map_server. Nav2 cannot be installed on the test machines, so this is the
check that can run here; it is written from map_io's rules, not from sessgan_core's reader:

* YAML: ``image`` (non-empty; a relative path is joined to the YAML file's directory),
  ``resolution``, ``origin`` (exactly 3 numbers), ``free_thresh``, ``occupied_thresh`` and
  ``negate`` (an int or a bool) are all required; ``mode`` is optional (trinary).
* Pixel (x, y), y counted from the image's top row, goes to grid row height - y - 1.
* shade = mean of the red, green and blue channels on 0..1 (in trinary mode an alpha
  channel's opacity is averaged in as a fourth channel); occ = shade if negate else
  1 - shade.
* trinary: occupied_thresh < occ -> 100, occ < free_thresh -> 0, else -1.
  scale: a pixel that is not opaque -> -1, then as trinary but values in between become
  rint((occ - free_thresh) / (occupied_thresh - free_thresh) * 100).
  raw: round(shade * 255) when within 0..100, else -1.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml
from PIL import Image

NAV2_REQUIRED_KEYS = ('image', 'resolution', 'origin', 'free_thresh', 'occupied_thresh',
                      'negate')


class Nav2Map(NamedTuple):
    data: np.ndarray
    """int8 (height, width), OccupancyGrid order (row 0 = the image's bottom row)."""
    resolution: float
    origin: tuple[float, float, float]


def nav2_load_map(yaml_file: str | os.PathLike) -> Nav2Map:
    """The OccupancyGrid map_server would publish for ``yaml_file``; AssertionError naming
    the rule when map_server would refuse it."""
    doc = yaml.safe_load(Path(yaml_file).read_text())
    missing = [key for key in NAV2_REQUIRED_KEYS if key not in doc]
    assert not missing, f'map_server requires the keys {missing}'
    image = str(doc['image'])
    assert image, 'The image tag was empty.'
    if not image.startswith('/'):
        image = (os.path.dirname(str(yaml_file)) or '.') + '/' + image
    resolution = float(doc['resolution'])
    origin = [float(value) for value in doc['origin']]
    assert len(origin) == 3, f"the 'origin' tag should have 3 elements, not {len(origin)}"
    free, occupied = float(doc['free_thresh']), float(doc['occupied_thresh'])
    mode = doc.get('mode', 'trinary')
    assert mode in ('trinary', 'scale', 'raw'), f'invalid map mode {mode!r}'
    negate = doc['negate']
    assert isinstance(negate, (int, bool)), f'negate must be an int or a bool, got {negate!r}'

    with Image.open(image) as opened:
        has_alpha = 'A' in opened.getbands()
        rgba = np.asarray(opened.convert('RGBA'), dtype=np.float64) / 255.0
    height, width = rgba.shape[:2]
    data = np.zeros(width * height, dtype=np.int8)
    for y in range(height):
        for x in range(width):
            red, green, blue, alpha = rgba[y, x]
            channels = [red, green, blue]
            if mode == 'trinary' and has_alpha:
                channels.append(alpha)
            shade = sum(channels) / len(channels)
            occ = shade if negate else 1.0 - shade
            if mode == 'trinary':
                cell = 100 if occupied < occ else 0 if occ < free else -1
            elif mode == 'scale':
                if alpha != 1.0:
                    cell = -1
                elif occupied < occ:
                    cell = 100
                elif occ < free:
                    cell = 0
                else:
                    cell = int(np.rint((occ - free) / (occupied - free) * 100.0))
            else:
                percent = round(shade * 255)
                cell = int(percent) if 0 <= percent <= 100 else -1
            data[width * (height - y - 1) + x] = cell
    assert all(math.isfinite(value) for value in (resolution, *origin))
    return Nav2Map(data.reshape(height, width), resolution, (origin[0], origin[1], origin[2]))
