"""`ros2 run sessgan_gen train`: train a TOAD-GAN pyramid on a scenario's example map, a token
map file (--map-file) or a map_server map (--map-yaml), checkpointing after every scale (resume
with --resume)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple, TextIO

import numpy as np
import torch

from sessgan_core.config_cli import parse_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.progress import ProgressPrinter, format_duration
from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command
from sessgan_core.scenarios import Scenario, get_scenario
from sessgan_gen.checkpoint import load_training_checkpoint, read_checkpoint, save_checkpoint
from sessgan_gen.errors import CheckpointError, SessganGenError
from sessgan_gen.seeding import seed_everything
from sessgan_gen.training import (
    TrainConfig,
    Trainer,
    TrainingState,
    check_training_map,
    config_dict,
    estimated_training_seconds,
    long_training_warning,
    resolve_config,
    same_training,
    training_metadata,
    validate_config,
)


class TrainingMap(NamedTuple):
    """The map a training run learns."""

    cells: np.ndarray
    scenario: Scenario
    source: str
    """Where it came from (recorded as map_source)."""
    origin: tuple[float, float, float]
    """Pose of its cell (0, 0) corner in the original map's frame ((0, 0, 0) for token
    maps)."""


def load_training_map(config: TrainConfig, log: TextIO | None = None) -> TrainingMap:
    """The map the config asks to learn, checked to be large enough; an imported map_server
    map is described on ``log`` (default stderr), with warnings for a map that is mostly wall
    or unknown."""
    from sessgan_core import token_map  # imported on use

    log = log or sys.stderr

    scenario = get_scenario(config.scenario)
    if config.map_file and config.map_yaml:
        raise SessganGenError('give --map-file or --map-yaml, not both')
    origin = (0.0, 0.0, 0.0)
    described = ''
    if config.map_yaml:
        from sessgan_core.map_server_io import import_facility_map

        imported = import_facility_map(config.map_yaml, scenario)
        loaded = imported.token_map
        origin = imported.origin
        source = str(Path(config.map_yaml).resolve())
        described = f' ({imported.summary()})'
        print(f'train: imported {config.map_yaml}: {imported.summary()}', file=log)
        for warning in imported.warnings():
            print(f'train: WARNING: {warning}', file=log)
        if origin[2] != 0.0:
            print(f'train: WARNING: the map origin is rotated (yaw {origin[2]} rad): the '
                  'learned map keeps it, but the generated maps and failure bags are placed '
                  'at its position unrotated (the simulator takes axis-aligned maps)', file=log)
    elif config.map_file:
        loaded = token_map.read_token_map(config.map_file)
        source = str(Path(config.map_file).resolve())
    else:
        loaded = token_map.load_example_map(scenario.name)
        source = f'example:{scenario.name}'
    loaded_scenario = getattr(loaded, 'scenario', scenario.name)
    loaded_name = getattr(loaded_scenario, 'name', loaded_scenario)
    if loaded_name != scenario.name:
        raise SessganGenError(
            f'map {source} is a {loaded_name!r} map, but --scenario is {scenario.name!r}')
    cells = np.asarray(loaded.cells, dtype=np.int64)
    try:
        check_training_map(cells)
    except ValueError as err:
        raise SessganGenError(f'map {source}{described}: {err}') from err
    return TrainingMap(cells, scenario, source, origin)


def imported_map_paths(output: Path) -> tuple[Path, Path]:
    """Where train writes the token map a --map-yaml became: (<output>.map.txt,
    <output>.map.yaml)."""
    return output.with_suffix('.map.txt'), output.with_suffix('.map.yaml')


def write_imported_map(output: Path, cells: np.ndarray, scenario: Scenario,
                       origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    """Write the token map learned from a map_server map next to the checkpoint: as tokens and
    as the map_server map it is at the scenario's cell size, at the original's ``origin`` (so it
    overlays the original in RViz)."""
    from sessgan_core.map_server_io import write_map_server
    from sessgan_core.token_map import TokenMap, tokens_to_occupancy, write_token_map

    text_path, yaml_path = imported_map_paths(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    token_map = TokenMap(scenario=scenario.name, cells=cells)
    write_token_map(text_path, token_map)
    write_map_server(yaml_path, tokens_to_occupancy(cells, scenario), scenario.cell_size,
                     origin)
    print(f'train: the map as learned ({token_map.width}x{token_map.height} cells of '
          f'{scenario.cell_size} m): {text_path} and {yaml_path}', file=sys.stderr)


class TotalEta:
    """Whole-run ETA: the cost model of :func:`estimated_training_seconds` (per scale, crops
    counted) for the work left, scaled by how much slower or faster than the model this run
    has been so far. The first seconds of a scale no longer decide the rate of every later
    scale, so the estimate does not jump (it read 115 h, then 7 min, within seconds)."""

    MIN_MEASURED_SECONDS = 2.0
    """Before this much of the run is measured, the model's own figure is shown."""

    def __init__(self, shapes: Sequence[tuple[int, int]], iterations: int, channels: int = 32,
                 crop_size: int = 0, clock: Callable[[], float] = time.perf_counter) -> None:
        self.costs = [estimated_training_seconds([shape], 1, channels, crop_size)
                      for shape in shapes]
        self.iterations = iterations
        self.clock = clock
        self.started: float | None = None
        self.origin = 0.0

    def _position(self, scale: int, done: int) -> float:
        """Model seconds of the work up to iteration ``done`` of ``scale``."""
        current = self.costs[scale] * done if scale < len(self.costs) else 0.0
        return sum(self.costs[:scale]) * self.iterations + current

    def estimate(self, scale: int, done: int) -> float:
        now = self.clock()
        position = self._position(scale, done)
        if self.started is None:  # a resumed run starts part-way
            self.started, self.origin = now, position
        left = self._position(len(self.costs), 0) - position
        elapsed, modelled = now - self.started, position - self.origin
        ratio = (elapsed / modelled if elapsed >= self.MIN_MEASURED_SECONDS and modelled > 0
                 else 1.0)
        return ratio * left


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status (0 success, 1 error, 2 bad options
    (nothing written), 130 interrupted)."""
    return run_command(lambda: run_training(argv), 'train: interrupted')


def run_training(argv: Sequence[str] | None) -> int:
    config = resolve_config(parse_config(
        TrainConfig, argv, prog='ros2 run sessgan_gen train',
        description='Train a SESS-GAN (TOAD-GAN) generator pyramid on one token map.'))
    try:
        validate_config(config)
        # The inputs the options name, read before anything is written: a map or checkpoint
        # that is not there or cannot be learned is a usage error too.
        training_map = check_inputs(config)
    except (SessganCoreError, SessganGenError, ValueError) as err:
        print(f'train: error: {err}', file=sys.stderr)
        return 2
    try:
        return train(config, training_map)
    except KeyboardInterrupt:
        # A checkpoint is written after each finished scale: before the first, none is there.
        print('train: interrupted; ' + (
            'run again with --resume to continue from the last finished scale'
            if Path(config.output).exists() else
            'no scale had finished, so nothing was saved: run the command again'),
            file=sys.stderr)
        return INTERRUPTED_STATUS
    except (SessganCoreError, SessganGenError, ValueError, OSError) as err:
        print(f'train: error: {err}', file=sys.stderr)
        return 1


def check_inputs(config: TrainConfig) -> TrainingMap:
    """The map to learn; SessganGenError when it, or the checkpoint --resume continues, cannot
    be used. Reads only."""
    training_map = load_training_map(config)
    if config.resume:
        if not Path(config.output).exists():
            raise CheckpointError(f'--resume: checkpoint {str(config.output)!r} does not exist')
        check_resumable(config, read_checkpoint(config.output)['metadata'], training_map.source)
    return training_map


def check_resumable(config: TrainConfig, metadata: dict, source: str) -> None:
    """CheckpointError unless the checkpoint ``metadata`` describes was trained with
    ``config``'s options on the map ``source``."""
    output = config.output
    differing = same_training(metadata.get('training_config', {}), config_dict(config))
    if differing:
        raise CheckpointError(
            f'--resume: checkpoint {str(output)!r} was trained with different options: '
            f'{", ".join(differing)}')
    if metadata.get('map_source') != source:
        raise CheckpointError(
            f'--resume: checkpoint {str(output)!r} learned {metadata.get("map_source")}, '
            f'not {source}')


def train(config: TrainConfig, training_map: TrainingMap | None = None) -> int:
    """Run (or resume) the training that ``config`` describes on ``training_map`` (default:
    :func:`check_inputs`'); writes config.output."""
    if config.threads:
        torch.set_num_threads(config.threads)
    cells, scenario, source, origin = (check_inputs(config) if training_map is None
                                       else training_map)
    output = Path(config.output)
    seed_everything(config.seed, config.deterministic)

    pyramid = None
    state = None
    if config.resume:
        pyramid, metadata, raw_state = load_training_checkpoint(output, config.device)
        check_resumable(config, metadata, source)
        state = TrainingState.from_dict(raw_state)
    trainer = Trainer(cells, scenario, config, pyramid, state)
    if pyramid is not None and trainer.pyramid.scale_shapes != pyramid.scale_shapes:
        raise CheckpointError(
            f'--resume: checkpoint {str(output)!r} has scales {pyramid.scale_shapes}, '
            f'this map needs {trainer.pyramid.scale_shapes}')
    shapes = trainer.pyramid.scale_shapes
    log = sys.stderr
    if config.map_yaml:
        write_imported_map(output, cells, scenario, origin)
    # width x height, as the import's summary and map_server say a size
    print(f'train: {scenario.name} map {source} {shapes[-1][1]}x{shapes[-1][0]} cells, '
          f'{len(shapes)} scales {[f"{w}x{h}" for h, w in shapes]}, '
          f'{config.iterations} iterations per scale, {config.channels} channels, '
          + (f'crops of {trainer.crop_size}x{trainer.crop_size} at larger scales, '
             if trainer.crop_size else '')
          + f'device {trainer.device}, seed {config.seed}', file=log)
    if trainer.finished:
        print(f'train: {output} is already complete', file=log)
        return 0
    if state is not None:
        print(f'train: resuming after scale {state.trained_scales}/{len(shapes)}', file=log)
    if warning := long_training_warning(shapes[trainer.state.trained_scales:],
                                        config.iterations, config.channels, trainer.crop_size):
        print(f'train: WARNING: {warning}', file=log)

    printer = ProgressPrinter(log) if config.progress else None
    eta = TotalEta(shapes, config.iterations, config.channels, trainer.crop_size)

    def progress(scale: int, num_scales: int, done: int, total: int) -> None:
        if printer is None:
            return
        if done == 1:
            h, w = shapes[scale]
            printer.start(f'scale {scale + 1}/{num_scales} {w}x{h}', total)
        printer.update(done, f'total ETA {format_duration(eta.estimate(scale, done))}')

    def checkpoint(pyramid, state: TrainingState) -> None:
        metadata = training_metadata(scenario, config, pyramid, state, source, cells,
                                     origin)
        save_checkpoint(output, pyramid, metadata, state.to_dict())
        result = state.scale_results[-1]
        print(f'train: scale {state.trained_scales}/{len(shapes)} done in '
              f'{result["seconds"]:.1f} s (noise amplitude {result["noise_amplitude"]:.4f}, '
              f'reconstruction accuracy {100 * result["reconstruction_accuracy"]:.1f} %); '
              f'saved {output}',
              file=log)

    trainer.run(progress=progress, on_scale_done=checkpoint)
    print(f'train: finished in {trainer.state.seconds:.1f} s of training; checkpoint {output} '
          f'and {output.with_suffix(".json")}', file=log)
    report_valid_tests(output, scenario, log)
    return 0


VALID_TEST_SAMPLES = 20
"""Maps sampled after training to tell how often the generator makes a valid test."""
FEW_VALID_TESTS = 0.25
"""A valid-test share below this warns: a campaign would spend most episodes on nothing."""


def report_valid_tests(output: Path, scenario: Scenario, log: TextIO) -> float:
    """Sample the trained generator and say how many of its maps are valid tests (a route
    exists between a start and a goal); warn loudly when few are. Returns the share."""
    from sessgan_gen.environment_sampler import EnvironmentSampler

    seeds = list(range(VALID_TEST_SAMPLES))
    environments = EnvironmentSampler().sample(seeds, output, scenario.name)
    share = sum(env.feasible for env in environments) / len(environments)
    print(f'train: {share:.0%} of {len(seeds)} sampled maps are valid tests', file=log)
    if share < FEW_VALID_TESTS:
        print(f'train: WARNING: only {share:.0%} of the maps this generator makes hold a route '
              f'for the {scenario.robot} robot: a campaign would find few or no valid tests. '
              'Is the map mostly wall (unknown space, negate)? Are its passages narrower than '
              'the robot needs?', file=log)
    return share


if __name__ == '__main__':
    sys.exit(main())
