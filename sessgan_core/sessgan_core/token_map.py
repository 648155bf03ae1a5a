"""Token maps: the plain text file format and conversions to occupancy values.

A token map is a numpy integer array ``cells[row, col]`` of shape (height, width)
whose values index ``Scenario.tokens``. Arrays are kept in nav_msgs/OccupancyGrid
order: row 0 is the lowest y (the bottom of the map as a human looks at it).
Files are written the way a human reads them, top row first, so reading and
writing flip the rows.

The text format::

    # scenario: factory
    # any other comment line
    WWWWWWWW
    WGGGGGGW
    WWWWWWWW

Lines starting with ``#`` are comments; ``# scenario: <name>`` names the
scenario. Every other line is one row of token characters, all of equal length.
Blank lines are allowed only before the first and after the last row.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_core.errors import MapFormatError, UnknownScenarioError
from sessgan_core.scenarios import BLOCKED, FREE, LOW_OBSTACLE, SCENARIOS, Scenario, get_scenario

EXAMPLE_MAP_DIR = Path(__file__).parent / 'data' / 'maps'
"""Folder of the shipped example maps, one ``<scenario>.txt`` per scenario."""

CELL_DTYPE = np.int64
"""dtype of token arrays returned by this module (torch's one_hot wants int64)."""

UNKNOWN = -1
"""OccupancyGrid value of an unknown cell."""

COMMON_FREE = 0
COMMON_LOW = 1
COMMON_BLOCKED = 2
COMMON_LEVELS = ('free', 'low', 'blocked')
"""The scenario-independent encoding of :func:`to_common_encoding`."""

_SCENARIO_KEY = 'scenario'

ScenarioLike = str | Scenario


def resolve_scenario(scenario: ScenarioLike) -> Scenario:
    """Return the Scenario for a name or a Scenario (UnknownScenarioError if unknown)."""
    if isinstance(scenario, Scenario):
        return scenario
    return get_scenario(scenario)


@dataclass
class TokenMap:
    """A grid of token ids of one scenario, in OccupancyGrid row order (row 0 = bottom)."""

    scenario: str
    cells: np.ndarray
    """Integer array (height, width) of token ids indexing the scenario's tokens."""

    @property
    def height(self) -> int:
        return int(self.cells.shape[0])

    @property
    def width(self) -> int:
        return int(self.cells.shape[1])

    def to_text(self) -> str:
        """The map in the text file format (top row first)."""
        return format_token_map(self)


def check_cells(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Return ``cells`` as a 2-D integer array, or raise MapFormatError naming the problem."""
    spec = resolve_scenario(scenario)
    array = np.asarray(cells)
    if array.ndim != 2 or array.size == 0:
        raise MapFormatError(
            f'token map of scenario {spec.name!r} must be a non-empty 2-D array, '
            f'got shape {array.shape}')
    if not np.issubdtype(array.dtype, np.integer):
        raise MapFormatError(
            f'token map of scenario {spec.name!r} must hold integer token ids, '
            f'got dtype {array.dtype}')
    bad = (array < 0) | (array >= spec.num_tokens)
    if bad.any():
        row, col = (int(v) for v in np.argwhere(bad)[0])
        raise MapFormatError(
            f'token map of scenario {spec.name!r}: cell (row {row}, col {col}) holds token id '
            f'{int(array[row, col])}; valid ids are 0..{spec.num_tokens - 1} {spec.tokens}')
    return array


def parse_token_map(
    text: str, scenario: str | None = None, source: str = '<string>'
) -> TokenMap:
    """Parse the text format; ``source`` names the file in error messages.

    The scenario comes from the ``scenario`` argument or the ``# scenario:``
    header; one of them is required, and when both are given they must agree.
    """
    header_scenario: str | None = None
    header_line = 0
    rows: list[tuple[int, str]] = []
    trailing_blank: int | None = None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.rstrip()
        if line.startswith('#'):
            key, sep, value = line[1:].partition(':')
            if sep and key.strip().lower() == _SCENARIO_KEY:
                header_scenario = value.strip()
                header_line = number
            continue
        if not line:
            if rows and trailing_blank is None:
                trailing_blank = number
            continue
        if trailing_blank is not None:
            raise MapFormatError(
                f'{source}, line {trailing_blank}: blank line inside the map rows '
                f'(rows continue at line {number})')
        rows.append((number, line))

    if header_scenario is not None and header_scenario not in SCENARIOS:
        raise MapFormatError(
            f'{source}, line {header_line}: unknown scenario {header_scenario!r}; '
            f'known scenarios: {", ".join(sorted(SCENARIOS))}')
    if scenario is not None and header_scenario is not None and scenario != header_scenario:
        raise MapFormatError(
            f'{source}, line {header_line}: the file is a {header_scenario!r} map but scenario '
            f'{scenario!r} was requested')
    name = scenario if scenario is not None else header_scenario
    if name is None:
        raise MapFormatError(
            f'{source}: no scenario given; add a "# scenario: <name>" line or pass scenario=')
    try:
        spec = get_scenario(name)
    except UnknownScenarioError as err:
        raise MapFormatError(f'{source}: {err}') from err
    if not rows:
        raise MapFormatError(f'{source}: the file holds no map rows (empty map)')

    width = len(rows[0][1])
    lookup = {char: index for index, char in enumerate(spec.tokens)}
    grid = np.empty((len(rows), width), dtype=CELL_DTYPE)
    for index, (number, line) in enumerate(rows):
        if len(line) != width:
            raise MapFormatError(
                f'{source}, line {number}: row has {len(line)} cells but the first row '
                f'(line {rows[0][0]}) has {width}; all rows must have equal length')
        for col, char in enumerate(line):
            token = lookup.get(char)
            if token is None:
                raise MapFormatError(
                    f'{source}, line {number}, column {col + 1}: character {char!r} is not a '
                    f'token of scenario {spec.name!r} (tokens: {"".join(spec.tokens)})')
            grid[index, col] = token
    # The file lists the top row first; arrays keep row 0 at the bottom.
    return TokenMap(scenario=spec.name, cells=np.ascontiguousarray(grid[::-1]))


def read_token_map(path: str | os.PathLike, scenario: str | None = None) -> TokenMap:
    """Read a token map text file (see the module docstring for the format)."""
    file_path = Path(path)
    try:
        text = file_path.read_text(encoding='utf-8')
    except FileNotFoundError as err:
        raise MapFormatError(f'token map file {str(file_path)!r} does not exist') from err
    except UnicodeDecodeError as err:
        raise MapFormatError(
            f'token map file {str(file_path)!r} is not UTF-8 text: {err}') from err
    except OSError as err:
        raise MapFormatError(f'cannot read token map file {str(file_path)!r}: {err}') from err
    return parse_token_map(text, scenario, source=str(file_path))


def format_token_map(token_map: TokenMap) -> str:
    """Return the text format of ``token_map``: header, then rows top first."""
    spec = resolve_scenario(token_map.scenario)
    cells = check_cells(token_map.cells, spec)
    chars = np.array(spec.tokens)
    lines = [
        f'# {_SCENARIO_KEY}: {spec.name}',
        f'# size: {cells.shape[1]}x{cells.shape[0]} cells (width x height), '
        f'{spec.cell_size} m per cell; top row first',
    ]
    lines.extend(''.join(row) for row in chars[cells[::-1]])
    return '\n'.join(lines) + '\n'


def write_token_map(path: str | os.PathLike, token_map: TokenMap) -> None:
    """Write ``token_map`` in the text format, atomically."""
    try:
        atomic_write_bytes(path, format_token_map(token_map).encode('utf-8'))
    except OSError as err:
        raise MapFormatError(f'cannot write token map file {str(path)!r}: {err}') from err


def load_example_map(scenario_name: str) -> TokenMap:
    """Load the shipped example (training) map of a scenario."""
    spec = get_scenario(scenario_name)
    return read_token_map(EXAMPLE_MAP_DIR / f'{spec.name}.txt', spec.name)


def tokens_to_occupancy(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """OccupancyGrid values (int8: free 0, low obstacle 50, blocked 100) of each cell."""
    spec = resolve_scenario(scenario)
    array = check_cells(cells, spec)
    return np.asarray(spec.occupancy, dtype=np.int8)[array]


def _token_for(spec: Scenario, occupancy_value: int) -> int | None:
    for token, value in enumerate(spec.occupancy):
        if value == occupancy_value:
            return token
    return None


def occupancy_to_tokens(occupancy: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Token ids for an OccupancyGrid array (values -1..100), in the same row order.

    0 maps to the scenario's free token and 100 to its blocked token. Unknown
    (-1) maps to blocked: a test map must not invent free space. Any value
    strictly between 0 and 100 (50 in our maps; map_server's scale mode gives
    others) is a low obstacle where the scenario has one (the drone's O) and
    blocked elsewhere, the conservative choice for a ground robot or a car.
    Values outside -1..100 raise MapFormatError.
    """
    spec = resolve_scenario(scenario)
    values = np.asarray(occupancy)
    if values.ndim != 2 or values.size == 0:
        raise MapFormatError(f'occupancy grid must be a non-empty 2-D array, got {values.shape}')
    bad = (values < UNKNOWN) | (values > BLOCKED)
    if bad.any():
        row, col = (int(v) for v in np.argwhere(bad)[0])
        raise MapFormatError(
            f'occupancy grid cell (row {row}, col {col}) holds {int(values[row, col])}; '
            'OccupancyGrid values are -1 (unknown) or 0..100')
    free = _token_for(spec, FREE)
    blocked = _token_for(spec, BLOCKED)
    if free is None or blocked is None:
        raise MapFormatError(
            f'scenario {spec.name!r} lacks a free or a blocked token; cannot convert occupancy')
    low = _token_for(spec, LOW_OBSTACLE)
    cells = np.full(values.shape, blocked, dtype=CELL_DTYPE)
    cells[values == FREE] = free
    cells[(values > FREE) & (values < BLOCKED)] = blocked if low is None else low
    return cells


def to_common_encoding(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Scenario-independent levels (uint8): 0 free, 1 low obstacle, 2 blocked.

    Used to compare maps of different scenarios (e.g. the TPKL matrix).
    """
    spec = resolve_scenario(scenario)
    array = check_cells(cells, spec)
    level = {FREE: COMMON_FREE, LOW_OBSTACLE: COMMON_LOW, BLOCKED: COMMON_BLOCKED}
    table = np.array([level[value] for value in spec.occupancy], dtype=np.uint8)
    return table[array]


def token_maps_to_common(maps: Sequence[TokenMap]) -> list[np.ndarray]:
    """Convenience: :func:`to_common_encoding` of every map of a list."""
    return [to_common_encoding(item.cells, item.scenario) for item in maps]
