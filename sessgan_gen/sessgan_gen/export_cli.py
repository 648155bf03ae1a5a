"""`ros2 run sessgan_gen export`: write any map of the project as a map_server map (PGM + YAML)
that Nav2's map_server, RViz or an image viewer loads.

Exactly one source:

* ``--map-file tokens.txt``: a token map (an example map, or the ``<checkpoint>.map.txt`` that
  ``train --map-yaml`` wrote), at its scenario's cell size, origin (0, 0);
* ``--generate``: the map a generator checkpoint (``--checkpoint``, default the scenario's
  shipped one) samples from ``--seed``, as the generator node would publish it;
* ``--bag bags/<run>/<episode>``: the map of a failure bag (a failing map), with its origin.

The YAML goes to ``--output``, the PGM beside it (same name, .pgm).
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sessgan_core.config_cli import parse_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.ros_spin import run_command
from sessgan_gen.errors import CheckpointError, SessganGenError


@dataclass
class ExportConfig:
    """What to export, and where; the ``export`` command's options."""

    output: str = ''
    """map_server YAML to write; the PGM goes beside it."""
    map_file: str = ''
    """Token map text file to export."""
    generate: bool = False
    """Export the map a generator checkpoint samples from --seed."""
    checkpoint: str = ''
    """Generator checkpoint for --generate; empty: the scenario's shipped checkpoint."""
    scenario: str = ''
    """Scenario of --generate; empty: the checkpoint's (factory without --checkpoint)."""
    seed: int = 0
    """Seed of the map --generate samples."""
    width: int = 0
    """Width in cells of the map --generate samples; 0: the size of the map the
    checkpoint learned (your facility's)."""
    height: int = 0
    """Height in cells of the map --generate samples; 0: the size of the map the
    checkpoint learned (your facility's)."""
    bag: str = ''
    """Failure bag directory whose map to export."""


def check_options(config: ExportConfig) -> Path:
    """The YAML path to write, or SessganGenError naming the first option that cannot work;
    nothing is written."""
    sources = [name for name, given in (('--map-file', config.map_file),
                                        ('--generate', config.generate), ('--bag', config.bag))
               if given]
    if len(sources) != 1:
        raise SessganGenError(f'give exactly one of --map-file, --generate, --bag (got '
                              f'{", ".join(sources) or "none"})')
    if not config.output:
        raise SessganGenError('--output (the map_server YAML to write) is required')
    output = Path(config.output)
    if output.suffix.lower() not in ('.yaml', '.yml'):
        raise SessganGenError(f'--output {output} must name a .yaml file (the PGM goes beside '
                              'it)')
    for option, value in (('--seed', config.seed), ('--width', config.width),
                          ('--height', config.height)):
        if value < 0:
            raise SessganGenError(f'{option} must be >= 0, got {value}')
    if config.scenario:
        from sessgan_core.scenarios import get_scenario

        get_scenario(config.scenario)
    if config.map_file and not Path(config.map_file).is_file():
        raise SessganGenError(f'--map-file {config.map_file} does not exist')
    if config.checkpoint:  # a missing, truncated or foreign file is a bad option too
        from sessgan_gen.checkpoint import read_checkpoint

        try:
            read_checkpoint(config.checkpoint)
        except CheckpointError as err:
            raise SessganGenError(f'--checkpoint: {err}') from err
    if config.map_file:  # a file that is no token map is a bad option too
        from sessgan_core.token_map import read_token_map

        read_token_map(config.map_file)
    if config.bag and not Path(config.bag).is_dir():
        raise SessganGenError(f'--bag {config.bag}: no such directory')
    if config.bag and not (Path(config.bag) / 'map.yaml').is_file():
        raise SessganGenError(f'{config.bag} is no failure bag: it has no map.yaml')
    if config.generate:  # another scenario's checkpoint, a size it cannot make: bad options
        from sessgan_gen.environment_sampler import resolve_sample_size

        pyramid, metadata = sampler().load(config.checkpoint or None,
                                           generated_scenario(config))
        resolve_sample_size(pyramid, metadata, (config.height, config.width),
                            config.scenario)
    return output


@functools.cache
def sampler() -> Any:
    """One EnvironmentSampler for the checks and the export: it loads a checkpoint once."""
    from sessgan_gen.environment_sampler import EnvironmentSampler

    return EnvironmentSampler()


def generated_scenario(config: ExportConfig) -> str | None:
    """The scenario --generate asks for: --scenario's, else the checkpoint's own (None), else
    the factory's shipped generator."""
    return config.scenario or (None if config.checkpoint else 'factory')


def export(config: ExportConfig) -> Path:
    """Write the map ``config`` names; returns the YAML path. SessganGenError (or ValueError)
    says what is wrong with the options or the source."""
    output = check_options(config)
    from sessgan_core.map_server_io import (
        export_environment,
        export_token_map,
        read_map_server,
        write_map_server,
    )

    output.parent.mkdir(parents=True, exist_ok=True)
    if config.map_file:
        from sessgan_core.token_map import read_token_map

        export_token_map(output, read_token_map(config.map_file))
    elif config.generate:
        from sessgan_gen.checkpoint import incomplete_warning

        scenario = generated_scenario(config)
        _, metadata = sampler().load(config.checkpoint or None, scenario)
        if warning := incomplete_warning(metadata, f'checkpoint {config.checkpoint}'):
            print(f'export: WARNING: {warning}', file=sys.stderr)
        environment = sampler().sample([config.seed], config.checkpoint or None, scenario,
                                     (config.height, config.width))[0]
        export_environment(output, environment)
        if not environment.feasible:
            print(f'export: WARNING: the map of seed {config.seed} holds no route between a '
                  'start and a goal for the robot: it is not a valid test', file=sys.stderr)
    else:
        bag = Path(config.bag)
        loaded = read_map_server(bag / 'map.yaml')
        write_map_server(output, loaded.occupancy, loaded.resolution, loaded.origin)
    return output


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 written, 1 error, 2 bad options: nothing
    written, 130 interrupted)."""
    return run_command(lambda: run_export(argv), 'export: interrupted')


def run_export(argv: Sequence[str] | None) -> int:
    config = parse_config(ExportConfig, argv, prog='ros2 run sessgan_gen export',
                          description=__doc__.split('\n\n')[0])
    try:
        check_options(config)
    except (SessganCoreError, SessganGenError, ValueError) as err:
        print(f'export: error: {err}', file=sys.stderr)
        return 2
    try:
        output = export(config)
    except (SessganCoreError, SessganGenError, ValueError, OSError) as err:
        print(f'export: error: {err}', file=sys.stderr)
        return 1
    print(f'{output} and {output.with_suffix(".pgm")}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
