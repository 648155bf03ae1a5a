"""Sample Environments (maps with start, goal and feasibility) from generator checkpoints.

The generator node is a thin wrapper around :class:`EnvironmentSampler`; the evolver sends
population members' weights (checkpoint bytes) and a generation's shared seeds.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sessgan_core.environment import MAX_CELLS_PER_SIDE, MAX_TOTAL_CELLS, Environment
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import MissionSpec
from sessgan_core.scenarios import get_scenario
from sessgan_core.valid_tests import make_environment
from sessgan_gen.checkpoint import (
    check_checkpoint_file,
    default_checkpoint_path,
    load_checkpoint,
    map_origin,
    map_size,
)
from sessgan_gen.errors import CheckpointError, SamplingRequestError
from sessgan_gen.model import GeneratorPyramid
from sessgan_gen.sampling import sample_token_maps
from sessgan_gen.track_cleanup import clean_token_map

MAX_SEEDS_PER_REQUEST = 4096

DEFAULT_MAX_CELLS_PER_REQUEST = 4 * 1024 * 1024
"""Default cap on the cells of all maps of one request (4,194,304: four 1024 x 1024 maps or
4096 factory maps of 32 x 32). Sampling costs about 6.5 us per cell on one core (a
1024 x 1024 map 6.4 s, 1024 maps of 32 x 32 6.8 s), so a request stays within half a
minute, well inside the campaign's 120 s wait for the generator."""


def environment_id(scenario: str, generation: int, member: int, seed: int) -> str:
    """Stable id of a sampled environment, used for bag and file names."""
    if generation >= 0 and member >= 0:
        return f'{scenario}-g{generation:03d}-m{member:02d}-s{seed}'
    return f'{scenario}-s{seed}'


class EnvironmentSampler:
    """Loads pyramids (cached) and turns seeds into Environments."""

    def __init__(self, device: str = 'cpu', cache_size: int = 4,
                 max_cells_per_request: int = DEFAULT_MAX_CELLS_PER_REQUEST) -> None:
        """``max_cells_per_request``: most cells (seeds x height x width) one ``sample`` call
        may produce; larger requests are refused before any sampling."""
        if max_cells_per_request < 1:
            raise SamplingRequestError(
                f'max_cells_per_request must be >= 1, got {max_cells_per_request}')
        self.device = device
        self.cache_size = cache_size
        self.max_cells_per_request = int(max_cells_per_request)
        self._cache: OrderedDict[str, tuple[GeneratorPyramid, dict]] = OrderedDict()

    def load(self, checkpoint: str | Path | bytes | None = None,
             scenario: str | None = None) -> tuple[GeneratorPyramid, dict]:
        """The pyramid of a checkpoint path, checkpoint bytes, or the scenario's shipped one."""
        if checkpoint is None or checkpoint == '' or checkpoint == b'':
            if not scenario:
                raise SamplingRequestError('neither a checkpoint nor a scenario was given')
            checkpoint = default_checkpoint_path(scenario)
        if isinstance(checkpoint, bytes):
            key = 'bytes:' + hashlib.sha256(checkpoint).hexdigest()
        else:
            path = Path(checkpoint)
            check_checkpoint_file(path, f'checkpoint {str(path)!r}')
            try:
                key = f'path:{path.resolve()}:{path.stat().st_mtime_ns}'
            except OSError as err:
                raise CheckpointError(f'checkpoint {str(path)!r} cannot be read: '
                                      f'{err.strerror}') from err
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        pyramid, metadata = load_checkpoint(checkpoint, device=self.device)
        if scenario and metadata.get('scenario') and metadata['scenario'] != scenario:
            raise CheckpointError(
                f'checkpoint is for scenario {metadata["scenario"]!r}, not {scenario!r}')
        self._cache[key] = (pyramid, metadata)
        while len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return pyramid, metadata

    def sample(self, seeds: Sequence[int], checkpoint: str | Path | bytes | None = None,
               scenario: str | None = None, size: tuple[int, int] | None = None,
               generation: int = -1, member: int = -1,
               mission: MissionSpec | None = None,
               post_process: bool = True,
               fleet: FleetSpec | None = None) -> list[Environment]:
        """One Environment per seed; map i depends only on seeds[i] and the weights.

        ``size`` is (height, width) in cells; None, or a zero side, means the checkpoint's
        training map's (:func:`resolve_sample_size`).
        ``mission``: stations before home drawn on each map (sessgan_core.missions); None: plain
        start -> goal episodes.
        ``post_process``: apply the scenario's ``track_cleanup`` (sessgan_gen.track_cleanup)
        to every map, when it has one (the race track); False gives the generator's raw maps.
        ``fleet``: robots under test on each map (sessgan_core.fleet); None: one.
        Every map sits at the checkpoint's training map origin (its ``map_origin``).
        """
        mission = (mission or MissionSpec()).validate()
        fleet = (fleet or FleetSpec()).validate(mission.stations)
        if scenario:
            get_scenario(scenario)  # UnknownScenarioError names the known ones
        if len(seeds) > MAX_SEEDS_PER_REQUEST:
            raise SamplingRequestError(
                f'{len(seeds)} seeds in one request; at most {MAX_SEEDS_PER_REQUEST}')
        pyramid, metadata = self.load(checkpoint, scenario)
        scenario_name = scenario or metadata.get('scenario')
        if not scenario_name:
            raise SamplingRequestError('the checkpoint names no scenario: give one')
        spec = get_scenario(scenario_name)
        height, width = resolve_sample_size(pyramid, metadata, size, scenario_name)
        origin = map_origin(metadata)
        if len(seeds) * height * width > self.max_cells_per_request:
            raise SamplingRequestError(
                f'{len(seeds)} maps of {height}x{width} are {len(seeds) * height * width:,} '
                f'cells, more than {self.max_cells_per_request:,} per request '
                '(max_cells_per_request): ask for fewer or smaller maps at a time')
        maps = list(sample_token_maps(pyramid, [int(s) for s in seeds], size=(height, width)))
        if post_process and spec.track_cleanup is not None:
            maps = [clean_token_map(cells, spec) for cells in maps]
        return [
            make_environment(cells, spec, environment_id(spec.name, generation, member, int(seed)),
                             seed=int(seed), generation=generation, member=member,
                             mission=mission, fleet=fleet, origin=origin)
            for cells, seed in zip(maps, seeds)
        ]


def resolve_sample_size(pyramid: GeneratorPyramid, metadata: Mapping[str, Any],
                        size: Sequence[int] | None, scenario: str = '') -> tuple[int, int]:
    """The (height, width) in cells a request for ``size`` gets: a generator serves maps of
    the size of the map it learned (a facility's) unless asked otherwise; a zero side takes
    the learned map's. SamplingRequestError for a size the pyramid or a simulator cannot
    take."""
    learned = map_size(metadata)
    requested = (0, 0) if size is None else tuple(int(v) for v in size)
    if len(requested) != 2 or min(requested) < 0:
        raise SamplingRequestError(f'size must be (height, width) >= 0, got {size}')
    height, width = (side or default for side, default in zip(requested, learned))
    label = f'this {scenario} generator' if scenario else 'this generator'
    min_side = min_sample_side(pyramid)
    if not all(min_side <= side <= MAX_CELLS_PER_SIDE for side in (height, width)):
        raise SamplingRequestError(
            f'size {height}x{width} cells is outside {min_side}..{MAX_CELLS_PER_SIDE} per '
            f'side for {label}')
    if height * width > MAX_TOTAL_CELLS:
        raise SamplingRequestError(
            f'size {height}x{width} is {height * width:,} cells a map, more than the '
            f'{MAX_TOTAL_CELLS:,} a simulator accepts')
    return height, width


def min_sample_side(pyramid: GeneratorPyramid) -> int:
    """Smallest side that keeps every pyramid scale at least 3 cells wide."""
    coarsest = min(min(shape) for shape in pyramid.scale_shapes)
    finest = min(pyramid.size)
    return max(3, -(-3 * finest // max(1, coarsest)))
