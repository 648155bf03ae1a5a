"""map_server maps (PGM image + YAML) in and out, as Nav2's map_server reads them.

Reading follows nav2_map_server's ``loadMapYaml``/``loadMapFromFile``: for each
pixel, shade = value / maxval, occ = shade if ``negate`` else 1 - shade;

* ``trinary`` (default): occ > occupied_thresh -> 100, occ < free_thresh -> 0,
  otherwise unknown -1;
* ``scale``: as trinary, but values in between become
  rint((occ - free_thresh) / (occupied_thresh - free_thresh) * 100);
* ``raw``: round(shade * 255) when it is 0..100, otherwise -1.

Image rows are stored top row first; the returned arrays are in OccupancyGrid
order (row 0 = lowest y). PGM images (P5 binary or P2 ASCII, 8 or 16 bit) are read
exactly; other images map_server loads (PNG, BMP, ...) through Pillow, the shade
being the mean of the colour channels as map_server computes it. ``image``,
``resolution`` and ``origin`` (3 elements, as map_server insists) are required; a
missing ``negate`` reads as 0, missing thresholds as map_saver's defaults (0.65, 0.25).

Importing for training (:func:`import_facility_map`) crops a SLAM map to its known
region first: the unknown margin a SLAM map has around the mapped area is outside the
map, not wall, so it must not count as part of the facility.

Writing produces a P5 PGM and a YAML that Nav2's map_server loads: free 0 ->
254 (white, as map_saver writes free space), blocked 100 -> 0 (black). A grid
holding values strictly between 0 and 100 (our low obstacles, 50) is written
in ``scale`` mode with each value v as the grey that map_server's scale mode
reads back as exactly v (50 -> 140, a mid grey), so Nav2, RViz and this module
all load a low obstacle as 50 rather than as unknown. Otherwise the YAML says
``trinary`` and unknown -1 is written as mid grey 127, which reads back as unknown. Both files are
written atomically (temporary file, then os.replace).
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml
from PIL import Image

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_core.environment import MAX_CELLS_PER_SIDE, Environment
from sessgan_core.errors import MapFormatError
from sessgan_core.grid_search import flat_grid, label_regions, union_roots
from sessgan_core.route_certificate import required_clearances
from sessgan_core.scenarios import BLOCKED, FREE
from sessgan_core.token_map import (
    UNKNOWN,
    ScenarioLike,
    TokenMap,
    check_cells,
    occupancy_to_tokens,
    resolve_scenario,
    tokens_to_occupancy,
)
from sessgan_core.validation import require_positive

WRITTEN_OCCUPIED_THRESH = 0.65
WRITTEN_FREE_THRESH = 0.196
"""The thresholds this project writes into a map's YAML: map_saver's since mid-2025."""
MAP_MODES = ('trinary', 'scale', 'raw')
FREE_PIXEL = 254
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 127
"""Mid grey: occ 0.502 lies between the thresholds we write, so it reads back as unknown
under any thresholds near them (map_saver's 205, occ 0.196, read as free under the
free_thresh 0.25 it wrote before mid-2025)."""
MAP_SAVER_UNKNOWN_PIXEL = 205
"""The grey map_saver writes for unknown cells in trinary mode."""
MAX_IMAGE_SIDE = 1 << 16
"""Images larger than this per side are rejected (a corrupt header, not a map)."""


class MapServerMap(NamedTuple):
    """An occupancy grid read from a map_server YAML."""

    occupancy: np.ndarray
    """int8 array (height, width), OccupancyGrid order and values (-1, 0..100)."""
    resolution: float
    """Metres per cell."""
    origin: tuple[float, float, float]
    """Pose (x m, y m, yaw rad) of the lower-left corner of cell (0, 0)."""


class MapMetadata(NamedTuple):
    """The keys of a map_server YAML, validated."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str


# --- PGM ----------------------------------------------------------------------------------------


def _pgm_header(data: bytes, source: str) -> tuple[str, list[int], int]:
    """Return (magic, [width, height, maxval], offset just after the header's last number)."""
    magic = data[:2].decode('latin-1')
    if magic not in ('P5', 'P2'):
        raise MapFormatError(
            f'{source}: not a PGM image (magic {data[:2]!r}; expected b"P5" or b"P2")')
    numbers: list[int] = []
    pos = 2
    size = len(data)
    while len(numbers) < 3:
        while pos < size and data[pos:pos + 1].isspace():
            pos += 1
        if pos < size and data[pos:pos + 1] == b'#':
            while pos < size and data[pos:pos + 1] not in (b'\n', b'\r'):
                pos += 1
            continue
        start = pos
        while pos < size and data[pos:pos + 1].isdigit():
            pos += 1
        if start == pos:
            what = ('width', 'height', 'maxval')[len(numbers)]
            found = 'end of file' if pos >= size else repr(data[pos:pos + 1])
            raise MapFormatError(
                f'{source}: truncated or malformed PGM header: expected the {what}, '
                f'found {found} at byte {pos}')
        numbers.append(int(data[start:pos]))
    return magic, numbers, pos


def read_pgm(path: str | os.PathLike) -> tuple[np.ndarray, int]:
    """Read a PGM (P5 or P2) image: (uint16 array (height, width), top row first; maxval).

    Not Pillow: it rescales an image whose maxval is not 255 (or 65535) to 8 (16) bits and
    drops the maxval, while map_server's thresholds apply to value / maxval exactly; with
    maxval 100, the value 35 (occ 0.65, unknown under the default occupied_thresh 0.65)
    became 89 / 255 (occ 0.651: occupied). Writing, where we choose the format, uses Pillow.
    """
    source = str(path)
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError as err:
        raise MapFormatError(f'map image {source!r} does not exist') from err
    except OSError as err:
        raise MapFormatError(f'cannot read map image {source!r}: {err}') from err
    magic, (width, height, maxval), pos = _pgm_header(data, source)
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
        raise MapFormatError(
            f'{source}: PGM size {width}x{height} is outside 1..{MAX_IMAGE_SIDE} per side')
    if not 1 <= maxval <= 65535:
        raise MapFormatError(f'{source}: PGM maxval {maxval} is outside 1..65535')
    count = width * height
    if magic == 'P5':
        # Exactly one whitespace byte separates the header from the raster.
        if pos >= len(data) or not data[pos:pos + 1].isspace():
            raise MapFormatError(f'{source}: truncated PGM: no pixel data after the header')
        pos += 1
        sample = np.dtype('u1') if maxval < 256 else np.dtype('>u2')
        need = count * sample.itemsize
        have = len(data) - pos
        if have < need:
            raise MapFormatError(
                f'{source}: truncated PGM: {width}x{height} pixels need {need} bytes of data, '
                f'found {have}')
        pixels = np.frombuffer(data, dtype=sample, count=count, offset=pos).astype(np.uint16)
    else:
        text = data[pos:].decode('latin-1')
        tokens = ' '.join(line.split('#', 1)[0] for line in text.splitlines()).split()
        if len(tokens) < count:
            raise MapFormatError(
                f'{source}: truncated PGM: {width}x{height} pixels expected, found {len(tokens)}')
        try:
            pixels = np.array([int(token) for token in tokens[:count]], dtype=np.int64)
        except ValueError as err:
            raise MapFormatError(
                f'{source}: PGM P2 pixel data holds a non-integer: {err}') from err
        if pixels.min() < 0:
            raise MapFormatError(f'{source}: PGM P2 pixel data holds a negative value')
    if int(pixels.max()) > maxval:
        raise MapFormatError(
            f'{source}: a pixel value {int(pixels.max())} exceeds the PGM maxval {maxval}')
    return pixels.reshape(height, width).astype(np.uint16), maxval


def encode_pgm(pixels: np.ndarray) -> bytes:
    """Encode an 8-bit (height, width) array, top row first, as a binary P5 PGM (maxval
    255)."""
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels, dtype=np.uint8), mode='L').save(buffer, 'PPM')
    return buffer.getvalue()


# --- YAML ---------------------------------------------------------------------------------------


def _number(document: dict, key: str, source: str) -> float:
    if key not in document:
        raise MapFormatError(f'{source}: required key {key!r} is missing (map_server '
                             'requires it)')
    value = document[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapFormatError(f'{source}: {key!r} must be a finite number, got {value!r}')
    return float(value)


def read_map_yaml(yaml_path: str | os.PathLike) -> MapMetadata:
    """Read and validate a map_server YAML; the image path is resolved against its folder."""
    path = Path(yaml_path).expanduser()
    source = str(path)
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError as err:
        raise MapFormatError(f'map YAML {source!r} does not exist') from err
    except UnicodeDecodeError as err:  # the image given for its YAML, most likely
        raise MapFormatError(f'{source!r} is no map YAML (not text: an image? give the .yaml '
                             'that names the image)') from err
    except OSError as err:
        raise MapFormatError(f'cannot read map YAML {source!r}: {err}') from err
    try:
        document: Any = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise MapFormatError(f'{source}: invalid YAML: {err}') from err
    if document is None:
        raise MapFormatError(f'{source}: the file is empty; a map_server YAML names at least '
                             'image, resolution and origin')
    if not isinstance(document, dict):
        raise MapFormatError(
            f'{source}: expected a mapping of map_server keys (image, resolution, origin, ...), '
            f'got {type(document).__name__}')

    image = document.get('image')
    if image is None:
        raise MapFormatError(f"{source}: required key 'image' is missing")
    if not isinstance(image, str) or not image.strip():
        raise MapFormatError(f"{source}: 'image' must be a non-empty file name, got {image!r}")
    image_path = Path(image).expanduser()
    if not image_path.is_absolute():
        image_path = path.parent / image_path

    resolution = _number(document, 'resolution', source)
    if resolution <= 0:
        raise MapFormatError(
            f"{source}: 'resolution' must be a positive number of metres per cell, "
            f'got {resolution}')

    if 'origin' not in document:
        raise MapFormatError(f"{source}: required key 'origin' is missing")
    origin = document['origin']
    if (not isinstance(origin, (list, tuple))
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in origin)):
        raise MapFormatError(
            f"{source}: 'origin' must be a list [x, y, yaw] of finite numbers, got {origin!r}")
    if len(origin) != 3:  # map_server's loadMapYaml refuses any other count, [x, y] too
        raise MapFormatError(
            f"{source}: 'origin' must be a list [x, y, yaw] of 3 numbers, as map_server "
            f'requires; got {len(origin)} elements {origin!r}')
    origin3 = (float(origin[0]), float(origin[1]), float(origin[2]))

    # map_server's loadMapYaml requires negate and both thresholds (only mode has a default).
    if 'negate' not in document:
        raise MapFormatError(f"{source}: required key 'negate' is missing (map_server "
                             'requires it: 0 for the usual black walls)')
    negate_value = document['negate']
    if isinstance(negate_value, bool) or negate_value in (0, 1):
        negate = bool(negate_value)
    else:
        raise MapFormatError(f"{source}: 'negate' must be 0, 1, true or false, "
                             f'got {negate_value!r}')

    occupied = _number(document, 'occupied_thresh', source)
    free = _number(document, 'free_thresh', source)
    if not (0.0 <= free < occupied <= 1.0):
        raise MapFormatError(
            f'{source}: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, '
            f'got free_thresh {free}, occupied_thresh {occupied}')

    mode = document.get('mode', 'trinary')
    if not isinstance(mode, str) or mode.lower() not in MAP_MODES:
        raise MapFormatError(f"{source}: 'mode' must be one of {MAP_MODES}, got {mode!r}")
    return MapMetadata(image_path, resolution, origin3, negate, occupied, free, mode.lower())


def pixels_to_occupancy(pixels: np.ndarray, maxval: int, metadata: MapMetadata,
                        translucent: np.ndarray | None = None) -> np.ndarray:
    """Apply map_server's thresholding; ``pixels`` top row first, result in OccupancyGrid order.
    ``translucent``: where (top row first) the image's alpha channel is not opaque, unknown
    in scale mode as map_server makes it."""
    shade = pixels.astype(np.float64) / float(maxval)
    occ = shade if metadata.negate else 1.0 - shade
    if metadata.mode == 'raw':
        percent = np.round(shade * 255.0)
        grid = np.where((percent >= 0) & (percent <= 100), percent, UNKNOWN)
    else:
        grid = np.full(shade.shape, UNKNOWN, dtype=np.float64)
        if metadata.mode == 'scale':
            grid = np.rint((occ - metadata.free_thresh)
                           / (metadata.occupied_thresh - metadata.free_thresh) * 100.0)
        grid = np.where(occ > metadata.occupied_thresh, BLOCKED, grid)
        grid = np.where(occ < metadata.free_thresh, FREE, grid)
        if metadata.mode == 'scale' and translucent is not None:
            grid = np.where(translucent, UNKNOWN, grid)
    return np.ascontiguousarray(grid.astype(np.int8)[::-1])


def read_image(path: Path, mode: str = 'trinary') -> tuple[np.ndarray, int, np.ndarray | None]:
    """A non-PGM map image (PNG, BMP, ...) as (uint16 shades (height, width), top row first;
    maxval; where its alpha channel is not opaque, None without one), the shade of a colour
    pixel being the mean of its colour channels as map_server computes it: in trinary
    ``mode`` an alpha channel's opacity is averaged in as a fourth channel (a transparent
    white pixel is grey, unknown under the usual thresholds); in scale mode a pixel that is
    not opaque is unknown (:func:`pixels_to_occupancy`)."""
    source = str(path)
    translucent = None
    if not path.is_file():
        raise MapFormatError(f'map image {source!r} does not exist')
    try:
        with Image.open(path) as image:
            image.load()
            if image.mode in ('I;16', 'I;16B', 'I;16L', 'I'):
                array = np.asarray(image, dtype=np.int64)
                maxval = 65535
            else:
                alpha = 'A' in image.getbands() or 'transparency' in image.info
                colour = np.asarray(image.convert('RGBA' if alpha else 'RGB'), dtype=np.float64)
                channels = 4 if alpha and mode == 'trinary' else 3
                array = np.rint(colour[..., :channels].mean(axis=2))
                maxval = 255
                if alpha:
                    translucent = colour[..., 3] < 255
    except (OSError, ValueError, Image.DecompressionBombError) as err:
        raise MapFormatError(f'cannot read map image {source!r}: {err}') from err
    if array.ndim != 2 or array.size == 0:
        raise MapFormatError(f'map image {source!r} has no pixels')
    if max(array.shape) > MAX_IMAGE_SIDE:
        raise MapFormatError(f'{source}: image size {array.shape[1]}x{array.shape[0]} is '
                             f'outside 1..{MAX_IMAGE_SIDE} per side')
    return np.clip(array, 0, maxval).astype(np.uint16), maxval, translucent


def read_map_pixels(metadata: MapMetadata) -> tuple[np.ndarray, int, np.ndarray | None]:
    """The map image's shades (top row first), their maxval and where its alpha channel is
    not opaque (:func:`read_image`; None for a PGM, which has none)."""
    if metadata.image.suffix.lower() in ('.pgm', ''):
        return (*read_pgm(metadata.image), None)
    return read_image(metadata.image, metadata.mode)


def read_map_server(yaml_path: str | os.PathLike) -> MapServerMap:
    """Read a map_server map: (occupancy int8 in OccupancyGrid order, resolution, origin)."""
    metadata = read_map_yaml(yaml_path)
    pixels, maxval, translucent = read_map_pixels(metadata)
    return MapServerMap(pixels_to_occupancy(pixels, maxval, metadata, translucent),
                        metadata.resolution, metadata.origin)


def map_saver_unknown(pixels: np.ndarray, maxval: int, metadata: MapMetadata) -> np.ndarray:
    """Where (OccupancyGrid order) a trinary map holds map_saver's unknown grey, 205, that
    map_server reads as free: Nav2's map_saver wrote ``free_thresh: 0.25`` into trinary YAMLs
    until mid-2025 (navigation2 pull request 5278), under which 205 (occ 0.196) is free, so
    every SLAM map it saved would make its unexplored space floor."""
    unknown_occ = 1.0 - MAP_SAVER_UNKNOWN_PIXEL / 255.0
    if (metadata.mode != 'trinary' or metadata.negate or maxval != 255
            or unknown_occ >= metadata.free_thresh):
        return np.zeros(np.shape(pixels), dtype=bool)
    return np.ascontiguousarray((np.asarray(pixels) == MAP_SAVER_UNKNOWN_PIXEL)[::-1])


# --- writing -----------------------------------------------------------------------------------


def occupancy_to_pixels(occupancy: np.ndarray, occupied_thresh: float = WRITTEN_OCCUPIED_THRESH,
                        free_thresh: float = WRITTEN_FREE_THRESH) -> tuple[np.ndarray, str]:
    """8-bit pixels (top row first) and the map mode that reads them back unchanged."""
    grid = np.asarray(occupancy)
    if grid.ndim != 2 or grid.size == 0:
        raise MapFormatError(f'occupancy grid must be a non-empty 2-D array, got {grid.shape}')
    if not np.issubdtype(grid.dtype, np.integer):
        raise MapFormatError(f'occupancy grid must hold integers, got dtype {grid.dtype}')
    values = grid.astype(np.int64)
    bad = (values < UNKNOWN) | (values > BLOCKED)
    if bad.any():
        row, col = (int(v) for v in np.argwhere(bad)[0])
        raise MapFormatError(f'occupancy cell (row {row}, col {col}) holds {values[row, col]}; '
                             'OccupancyGrid values are -1 or 0..100')
    between = (values > FREE) & (values < BLOCKED)
    unknown = values == UNKNOWN
    if between.any() and unknown.any():
        raise MapFormatError(
            'occupancy grid mixes unknown (-1) cells and values between 0 and 100: a PGM '
            'without an alpha channel cannot represent both')
    pixels = np.full(values.shape, FREE_PIXEL, dtype=np.uint8)
    pixels[values == BLOCKED] = OCCUPIED_PIXEL
    if between.any():
        mode = 'scale'
        # The grey that scale mode maps back to v: occ = free + v/100 * (occupied - free).
        occ = free_thresh + values / 100.0 * (occupied_thresh - free_thresh)
        grey = np.rint(255.0 * (1.0 - occ)).astype(np.int64)
        pixels[between] = grey[between].astype(np.uint8)
    else:
        mode = 'trinary'
        pixels[unknown] = UNKNOWN_PIXEL
    return np.ascontiguousarray(pixels[::-1]), mode


def _format_float(value: float) -> str:
    return repr(float(value))


def write_map_server(yaml_path: str | os.PathLike, occupancy: np.ndarray, resolution: float,
                     origin: Sequence[float] = (0.0, 0.0, 0.0)) -> Path:
    """Write ``<yaml_path>`` and the P5 PGM ``<stem>.pgm`` beside it; return the image path.

    ``occupancy`` is in OccupancyGrid order (row 0 = lowest y), ``resolution`` in
    metres per cell, ``origin`` (x m, y m[, yaw rad]) of the corner of cell (0, 0).
    """
    path = Path(yaml_path)
    if not (isinstance(resolution, (int, float)) and math.isfinite(resolution)
            and resolution > 0):
        raise MapFormatError(f'{path}: resolution must be a positive finite number of metres '
                             f'per cell, got {resolution!r}')
    if len(origin) not in (2, 3) or not all(math.isfinite(float(v)) for v in origin):
        raise MapFormatError(f'{path}: origin must be (x, y[, yaw]) finite numbers, '
                             f'got {tuple(origin)!r}')
    origin3 = (float(origin[0]), float(origin[1]), float(origin[2]) if len(origin) == 3 else 0.0)
    pixels, mode = occupancy_to_pixels(occupancy)
    image_path = path.with_suffix('.pgm')
    if image_path == path:
        raise MapFormatError(f'{path}: the YAML file must not end in .pgm')
    text = '\n'.join([
        f'image: {image_path.name}',
        f'mode: {mode}',
        f'resolution: {_format_float(resolution)}',
        f'origin: [{", ".join(_format_float(v) for v in origin3)}]',
        'negate: 0',
        f'occupied_thresh: {WRITTEN_OCCUPIED_THRESH}',
        f'free_thresh: {WRITTEN_FREE_THRESH}',
    ]) + '\n'
    try:
        atomic_write_bytes(image_path, encode_pgm(pixels))
        atomic_write_bytes(path, text.encode('utf-8'))
    except OSError as err:
        raise MapFormatError(f'cannot write map {str(path)!r}: {err}') from err
    return image_path


def export_environment(yaml_path: str | os.PathLike, environment: Environment) -> Path:
    """Write an Environment's occupancy grid as a map_server map; return the image path."""
    return write_map_server(yaml_path, environment.occupancy, environment.resolution,
                            (environment.origin[0], environment.origin[1], 0.0))


def export_token_map(yaml_path: str | os.PathLike, token_map: TokenMap) -> Path:
    """Write a token map as a map_server map at its scenario's cell size, origin (0, 0)."""
    spec = resolve_scenario(token_map.scenario)
    return write_map_server(yaml_path, tokens_to_occupancy(token_map.cells, spec),
                            spec.cell_size)


# --- import for training ------------------------------------------------------------------------


def _cover_ranges(source: int, target: int) -> list[tuple[int, int]]:
    """For each of ``target`` output cells, the input range [start, stop) it overlaps."""
    return [((index * source) // target, -((-(index + 1) * source) // target))
            for index in range(target)]


def resample_tokens(cells: np.ndarray, scenario: ScenarioLike,
                    size: tuple[int, int]) -> np.ndarray:
    """Token-aware resampling to ``size`` (height, width).

    Each output cell covers a rectangle of the input; it takes the token that
    ranks highest in the scenario's hierarchy among the input cells that
    rectangle overlaps (even partly), so thin walls and tracks survive.
    """
    spec = resolve_scenario(scenario)
    array = check_cells(cells, spec)
    height, width = (int(v) for v in size)
    if not (1 <= height <= MAX_CELLS_PER_SIDE and 1 <= width <= MAX_CELLS_PER_SIDE):
        raise MapFormatError(
            f'target size {height}x{width} (height x width) is outside 1..{MAX_CELLS_PER_SIDE} '
            'cells per side')
    if (height, width) == array.shape:
        return array.copy()
    rank = np.empty(spec.num_tokens, dtype=np.int64)
    rank[list(spec.hierarchy)] = np.arange(spec.num_tokens)
    ranked = rank[array]
    rows = np.stack([ranked[start:stop].max(axis=0)
                     for start, stop in _cover_ranges(array.shape[0], height)])
    pooled = np.stack([rows[:, start:stop].max(axis=1)
                       for start, stop in _cover_ranges(array.shape[1], width)], axis=1)
    return np.asarray(spec.hierarchy, dtype=np.int64)[pooled]


def import_map_server(yaml_path: str | os.PathLike, scenario: ScenarioLike,
                      size: tuple[int, int] | None = None) -> TokenMap:
    """Turn a map_server map into a token map of ``scenario`` for training.

    Thresholding as map_server does, then occupancy to tokens (unknown -1 counts
    as blocked; values between 0 and 100 are low obstacles for the drone and
    blocked otherwise, see :func:`occupancy_to_tokens`), then token-aware
    resampling to ``size`` (height, width) cells; None keeps the image's grid.
    """
    spec = resolve_scenario(scenario)
    loaded = read_map_server(yaml_path)
    cells = occupancy_to_tokens(loaded.occupancy, spec)
    if size is not None:
        cells = resample_tokens(cells, spec, size)
    return TokenMap(scenario=spec.name, cells=cells)


def cells_at_cell_size(pixels: tuple[int, int], resolution: float,
                       cell_size: float) -> tuple[int, int]:
    """(height, width) in cells of ``cell_size`` metres that cover an image of ``pixels``
    (height, width) at ``resolution`` metres per pixel: rounded up, at least one."""
    require_positive('cell size', cell_size, MapFormatError, ' m')
    # The tolerance keeps 120 px x 0.05 m / 0.5 m (11.999999999999998 or 12.000000000000002
    # in floating point) at 12 cells.
    height, width = (max(1, math.ceil(count * resolution / cell_size - 1e-9))
                     for count in pixels)
    return height, width


def pad_to_cells(occupancy: np.ndarray, size: tuple[int, int], resolution: float,
                 cell_size: float) -> np.ndarray:
    """``occupancy`` with unknown pixels added after its last row and column so that it spans
    ``size`` (height, width) cells of ``cell_size`` metres (to the nearest pixel): resampled
    to those cells, every cell then covers its own square of the map, not a stretched one."""
    height, width = (round(cells * cell_size / resolution) for cells in size)
    pad_rows, pad_cols = max(0, height - occupancy.shape[0]), max(0, width - occupancy.shape[1])
    return np.pad(occupancy, ((0, pad_rows), (0, pad_cols)), constant_values=UNKNOWN)


LOW_FREE_FRACTION = 0.2
"""An imported map with less free floor than this share of its cells gets a warning: the
example maps have 40 % (race track) to 74 % (drone), and a robot needs room for a route."""
LOW_KNOWN_FRACTION = 0.75
"""An imported map whose known region is less than this share of its cells (after cropping)
gets a warning: the unknown cells inside count as walls."""
SPECK_CELL_FRACTION = 0.25
"""An unknown speck inside free floor (:func:`specks`) smaller than this share of one
cell's area is floor that SLAM did not observe (a gap between laser rays), taken as free:
resampling would make each such speck a whole wall cell, four or more times its size, that
the generator learns as a pillar. A region of a quarter cell or more (0.25 m x 0.25 m for
0.5 m cells, 25 px at 0.05 m/px) is the size of an object the scan may have missed, so it
stays wall; at a resolution of half a cell or coarser no pixel is small enough."""


WALL_SPECK_CELL_FRACTION = 1 / 16
"""An occupied speck inside free floor (:func:`specks`) smaller than this share of one cell's
area (under 6.25 px at 0.05 m/px for 0.5 m cells: lidar noise, a table leg) is taken as floor:
resampling would make it a whole wall cell, 16 or more times its size, that the generator
learns as a pillar. Anything larger stays wall."""
SEALED_FLOOR_DROP = 0.1
"""A learned map whose robot reaches less of its floor from its largest region than the
original by more than this share (:func:`reachable_floor`) gets a warning: resampling to whole
cells closed openings the robot passes in the original."""


class FacilityImport(NamedTuple):
    """A map_server map imported for training (:func:`import_facility_map`)."""

    token_map: TokenMap
    """The token map at the scenario's cell size, cropped to the map's known region."""
    origin: tuple[float, float, float]
    """Pose (x m, y m, yaw rad) of the corner of the token map's cell (0, 0) in the original
    map's frame: the original origin moved to the cropped region, so the learned map overlays
    the original in RViz."""
    image_shape: tuple[int, int]
    """(height, width) in pixels of the original image."""
    known_box: tuple[int, int, int, int]
    """(first row, last row + 1, first column, last column + 1), OccupancyGrid order, of the
    pixels kept: the bounding box of the known (not unknown) pixels."""
    resolution: float
    """Metres per pixel of the original."""
    known_fraction: float
    """Share of the kept pixels that are known (the rest count as walls), after the specks of
    unknown inside free floor were taken as floor: what the generator learns from."""
    free_fraction: float
    """Share of the token map's cells that are free floor."""
    saver_unknown: int = 0
    """Pixels of map_saver's unknown grey taken as unknown where map_server would read them
    as free (:func:`map_saver_unknown`)."""
    floor_specks: int = 0
    """Specks of unknown inside free floor taken as floor (:func:`specks`)."""
    floor_speck_pixels: int = 0
    """Their pixels, all together."""
    wall_specks: int = 0
    """Specks of occupied pixels inside free floor taken as floor (:func:`specks`)."""
    wall_speck_pixels: int = 0
    """Their pixels, all together."""
    reachable: tuple[float, float] = (1.0, 1.0)
    """:func:`reachable_floor` of the original map (cropped, specks taken as floor) and of the
    learned one, for the scenario's robot on its route clearance."""

    def warnings(self) -> list[str]:
        """What a user should hear about this import (empty when nothing is odd)."""
        found = []
        if self.saver_unknown:
            found.append(
                f"{self.saver_unknown} pixels of grey {MAP_SAVER_UNKNOWN_PIXEL} (map_saver's "
                "unknown) would read as free under the YAML's free_thresh, as map_saver "
                'wrote it before mid-2025: they are taken as unknown (set free_thresh: 0.196 '
                "for Nav2's map_server to read them so too)")
        if self.free_fraction < LOW_FREE_FRACTION:
            found.append(
                f'only {self.free_fraction:.0%} of the imported map is free floor (less than '
                f'{LOW_FREE_FRACTION:.0%}): the generator will learn a map that is almost all '
                'wall, and its samples will rarely hold a route (check negate and the '
                'thresholds in the YAML: is free space white?)')
        original, learned = self.reachable
        if learned < original - SEALED_FLOOR_DROP:
            spec = resolve_scenario(self.token_map.scenario)
            need = 2 * required_clearances(spec)[1]
            found.append(
                f'resampling to {spec.cell_size} m cells closed openings: the largest open '
                f'region of the learned map holds {learned:.0%} of the floor the robot can '
                f'stand on, against {original:.0%} in the original. A door the robot passes '
                f'that became narrower than the {need:.2f} m its route needs (one cell) '
                'seals what lies behind it: check the learned map (the .map.pgm beside the '
                'checkpoint) and widen such doors in the original image if they matter')
        if self.known_fraction < LOW_KNOWN_FRACTION:
            found.append(
                f'{1 - self.known_fraction:.0%} of the mapped region is unknown and counts as '
                'wall: finish mapping it, or mark it free or occupied in an image editor')
        return found

    def summary(self) -> str:
        """One line: what was kept and what it became."""
        height, width = self.image_shape
        top, bottom, left, right = self.known_box
        cropped = ('' if (bottom - top, right - left) == (height, width) else
                   f', cropped to its known region of {right - left}x{bottom - top} px '
                   '(unknown outside the mapped area is outside the map)')
        spec = resolve_scenario(self.token_map.scenario)
        specks = ('' if not self.floor_specks else
                  f'; {self.floor_specks} specks of unknown inside free floor '
                  f'({self.floor_speck_pixels} px in all, each under '
                  f'{SPECK_CELL_FRACTION:.0%} of a cell) taken as floor')
        if self.wall_specks:
            specks += (f'; {self.wall_specks} specks of occupied pixels inside free floor '
                       f'({self.wall_speck_pixels} px in all, each under '
                       f'{WALL_SPECK_CELL_FRACTION:.1%} of a cell: lidar noise or objects '
                       'too small for a cell) taken as floor')
        return (f'{width}x{height} px at {self.resolution} m/px{cropped} -> '
                f'{self.token_map.width}x{self.token_map.height} cells of {spec.cell_size} m, '
                f'{self.free_fraction:.0%} free{specks}')


def known_bounding_box(occupancy: np.ndarray) -> tuple[int, int, int, int]:
    """(first row, last row + 1, first column, last column + 1) of the cells that are not
    unknown; MapFormatError if every cell is unknown."""
    known = np.asarray(occupancy) != UNKNOWN
    if not known.any():
        raise MapFormatError('every cell of the map is unknown: there is nothing to learn')
    rows = np.flatnonzero(known.any(axis=1))
    cols = np.flatnonzero(known.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _regions_8(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(label of each pixel of ``mask``, -1 elsewhere; pixel count of each label): its
    8-connected regions, :func:`label_regions`' 4-connected ones joined where two touch at a
    corner (each taking the smallest of their labels, so some labels count no pixel)."""
    grid = flat_grid(mask)
    regions = label_regions(grid)
    labels = regions.labels.reshape(-1, grid.stride)[1:-1, 1:-1]
    if not len(regions.sizes):
        return labels, regions.sizes
    corners = [(labels[:-1, :-1], labels[1:, 1:]), (labels[:-1, 1:], labels[1:, :-1])]
    root = union_roots(len(regions.sizes),
                       np.concatenate([x[(x >= 0) & (y >= 0)] for x, y in corners]),
                       np.concatenate([y[(x >= 0) & (y >= 0)] for x, y in corners]))
    merged = np.where(labels >= 0, root[labels], -1)
    return merged, np.bincount(root, weights=regions.sizes, minlength=len(root)).astype(np.int64)


def specks(occupancy: np.ndarray, value: int, max_pixels: float) -> tuple[np.ndarray, int]:
    """(mask, count) of the specks of ``value`` (unknown or occupied) inside free floor:
    8-connected regions of that value of fewer than ``max_pixels`` pixels whose every
    8-neighbour is free (0). One touching anything else (a wall, unknown, a low obstacle) or
    the array's edge, even at a corner, is not one. 8-connected, so that a diagonal chain (a
    gap between laser rays) is one region, measured as a whole, and a corner contact with a
    wall keeps it wall."""
    occupancy = np.asarray(occupancy)
    # Everything not free, in a ring for the array's edge: a speck is a region of it that
    # holds pixels of ``value`` only.
    not_free = np.pad(occupancy != FREE, 1, constant_values=True)
    labels, sizes = _regions_8(not_free)
    other = np.pad(occupancy != value, 1, constant_values=True) & not_free
    speck = (sizes < max_pixels) & (np.bincount(labels[other], minlength=len(sizes)) == 0)
    mask = (labels >= 0) & speck[labels]  # the ring makes one region at least
    return mask[1:-1, 1:-1], int(np.count_nonzero(speck & (sizes > 0)))


def reachable_floor(free: np.ndarray, resolution: float, radius: float) -> float:
    """Share of the floor a robot of ``radius`` m can stand on (every pixel within ``radius``
    along both axes free: a square, so a diagonal passage reads a little narrower) that lies
    in the largest 4-connected region of such floor: 1 where every room is open to the
    others, less where a room is sealed off; 0 without such floor."""
    free = np.asarray(free, dtype=bool)
    reach = max(0, int(math.ceil(radius / resolution - 1e-9)))
    # Blocked pixels in each (2 reach + 1)-square, from a summed-area table (the outside
    # counts as blocked).
    blocked = np.pad(~free, reach, constant_values=True)
    table = np.pad(blocked.cumsum(0, dtype=np.int32).cumsum(1, dtype=np.int32),
                   ((1, 0), (1, 0)))
    side = 2 * reach + 1
    height, width = free.shape
    window = (table[side:side + height, side:side + width] - table[:height, side:side + width]
              - table[side:side + height, :width] + table[:height, :width])
    stand = window == 0
    sizes = label_regions(flat_grid(stand)).sizes
    return float(sizes.max() / sizes.sum()) if len(sizes) else 0.0


def import_facility_map(yaml_path: str | os.PathLike, scenario: ScenarioLike) -> FacilityImport:
    """A map_server map as a token map of ``scenario`` at the scenario's cell size, for
    training on a facility's own map.

    A SLAM map (map_saver's output) is a rectangle of unknown space with the mapped area
    somewhere inside: the image is first cropped to the bounding box of its known pixels, since
    unknown space outside the mapped area is outside the facility, not part of it. Unknown
    pixels that remain inside the box count as walls (a test map must not invent floor), but
    specks inside free floor smaller than :data:`SPECK_CELL_FRACTION` of a cell
    (:func:`specks`) are floor that SLAM missed, taken as free: each would otherwise
    become a whole wall cell. ``known_fraction`` is measured after that.
    map_saver's unknown grey stays unknown where its old free_thresh would read it as free
    (:func:`map_saver_unknown`). Then :func:`import_map_server`'s conversion with the size
    that keeps the map's metres: an image of h x w pixels at r m/px becomes ceil(h*r/cell)
    x ceil(w*r/cell) cells of the scenario's ``cell_size``, the last row and column filled up
    with wall (:func:`pad_to_cells`). MapFormatError when the result exceeds the grid limits
    or holds no known pixel.
    """
    spec = resolve_scenario(scenario)
    metadata = read_map_yaml(yaml_path)
    pixels, maxval, translucent = read_map_pixels(metadata)
    occupancy = pixels_to_occupancy(pixels, maxval, metadata, translucent)
    saver_unknown = map_saver_unknown(pixels, maxval, metadata)
    occupancy[saver_unknown] = UNKNOWN
    loaded = MapServerMap(occupancy, metadata.resolution, metadata.origin)
    try:
        top, bottom, left, right = known_bounding_box(loaded.occupancy)
    except MapFormatError as err:
        raise MapFormatError(f'{yaml_path}: {err}') from err
    cropped = loaded.occupancy[top:bottom, left:right].copy()
    size = cells_at_cell_size(cropped.shape, loaded.resolution, spec.cell_size)
    if max(size) > MAX_CELLS_PER_SIDE:
        raise MapFormatError(
            f'{yaml_path}: {cropped.shape[1]}x{cropped.shape[0]} known pixels at '
            f'{loaded.resolution} m/px make {size[1]}x{size[0]} cells of {spec.cell_size} m, '
            f'more than {MAX_CELLS_PER_SIDE} per side')
    cell_pixels = (spec.cell_size / loaded.resolution) ** 2
    floor_specks, floor_speck_count = specks(cropped, UNKNOWN, SPECK_CELL_FRACTION * cell_pixels)
    cropped[floor_specks] = FREE
    wall_specks, wall_speck_count = specks(cropped, BLOCKED,
                                           WALL_SPECK_CELL_FRACTION * cell_pixels)
    cropped[wall_specks] = FREE
    # Walls (unknown) fill the last cell row and column, rather than the map being stretched
    # to whole cells: the learned map then overlays the original to the pixel.
    padded = pad_to_cells(cropped, size, loaded.resolution, spec.cell_size)
    cells = resample_tokens(occupancy_to_tokens(padded, spec), spec, size)
    x, y, yaw = loaded.origin
    # The origin is the pose of the corner of pixel (0, 0): move it along the map's own axes.
    dx, dy = left * loaded.resolution, top * loaded.resolution
    # Rounded to a nanometre, so the YAML says -1.6, not -1.5999999999999996.
    origin = (round(x + dx * math.cos(yaw) - dy * math.sin(yaw), 9),
              round(y + dx * math.sin(yaw) + dy * math.cos(yaw), 9), yaw)
    learned = tokens_to_occupancy(cells, spec)
    free = float(np.mean(learned == FREE))
    known = float(np.mean(cropped != UNKNOWN))
    # Both at about the original's pixel size (each cell split into as many), for one robot.
    split = max(1, round(spec.cell_size / loaded.resolution))
    learned_pixels = np.repeat(np.repeat(learned == FREE, split, axis=0), split, axis=1)
    radius = required_clearances(spec)[1]
    reachable = (reachable_floor(cropped == FREE, loaded.resolution, radius),
                 reachable_floor(learned_pixels, spec.cell_size / split, radius))
    return FacilityImport(TokenMap(scenario=spec.name, cells=cells), origin,
                          (int(loaded.occupancy.shape[0]), int(loaded.occupancy.shape[1])),
                          (top, bottom, left, right), loaded.resolution, known, free,
                          int(np.count_nonzero(saver_unknown)), floor_speck_count,
                          int(np.count_nonzero(floor_specks)), wall_speck_count,
                          int(np.count_nonzero(wall_specks)), reachable)


def import_map_server_for_scenario(yaml_path: str | os.PathLike,
                                   scenario: ScenarioLike) -> TokenMap:
    """The token map of :func:`import_facility_map` (cropped to the known region, at the
    scenario's cell size)."""
    return import_facility_map(yaml_path, scenario).token_map
