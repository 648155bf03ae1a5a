"""`ros2 run sessgan_gen report`: TPKL matrix, uniqueness table and sample maps of the
generators of every scenario (the paper's Fig. 11 and Table 1), as PNG and markdown."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from sessgan_core.config_cli import parse_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.ros_spin import run_command
from sessgan_core.scenarios import get_scenario
from sessgan_gen.checkpoint import read_checkpoint
from sessgan_gen.errors import CheckpointError, SessganGenError
from sessgan_gen.report import (
    REPORT_SCENARIOS,
    compute_report,
    tpkl_markdown,
    uniqueness_markdown,
    write_report,
)


@dataclass
class ReportConfig:
    """Options of the report command."""

    output_dir: str = 'sessgan_report'
    """Directory the report files (report.md, PNGs, metrics.json) are written to."""
    samples: int = 100
    """Maps sampled per scenario."""
    seed: int = 0
    """Base seed of the sampled maps."""
    scenarios: tuple[str, ...] = REPORT_SCENARIOS
    """Scenarios (rows and columns of the TPKL matrix)."""
    factory_checkpoint: str = ''
    """Factory generator checkpoint; empty: the shipped one."""
    racetrack_checkpoint: str = ''
    """Race-track generator checkpoint; empty: the shipped one."""
    drone_checkpoint: str = ''
    """Drone generator checkpoint; empty: the shipped one."""
    threads: int = 0
    """Torch CPU threads; 0 keeps torch's default."""


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 success, 1 error, 2 bad options: nothing
    written, 130 interrupted)."""
    return run_command(lambda: run_report(argv), 'report: interrupted')


def check_options(config: ReportConfig) -> list[str]:
    """The scenarios to report, or SessganGenError naming the first option that cannot
    work."""
    for option, value, least in (('--samples', config.samples, 1), ('--seed', config.seed, 0),
                                 ('--threads', config.threads, 0)):
        if value < least:
            raise SessganGenError(f'{option} must be >= {least}, got {value}')
    scenarios = list(config.scenarios)
    if not scenarios:
        raise SessganGenError('--scenarios names no scenario')
    for name in scenarios:
        get_scenario(name)
        checkpoint = getattr(config, f'{name}_checkpoint', '')
        if checkpoint:  # missing, truncated or foreign: a bad option, nothing written
            try:
                trained = read_checkpoint(checkpoint)['metadata']['scenario']
            except CheckpointError as err:
                raise SessganGenError(f'--{name}-checkpoint: {err}') from err
            if trained != name:
                raise SessganGenError(f'--{name}-checkpoint: {checkpoint} was trained for '
                                      f'scenario {trained!r}, not {name!r}')
    return scenarios


def run_report(argv: Sequence[str] | None) -> int:
    config = parse_config(
        ReportConfig, argv, prog='ros2 run sessgan_gen report',
        description='Write the TPKL matrix, uniqueness table and sample maps of the '
                    'generators (paper Fig. 11 and Table 1).')
    try:
        scenarios = check_options(config)
    except (SessganCoreError, SessganGenError) as err:
        print(f'report: error: {err}', file=sys.stderr)
        return 2
    if config.threads:
        torch.set_num_threads(config.threads)
    checkpoints = {name: getattr(config, f'{name}_checkpoint', '') for name in scenarios}
    try:
        data = compute_report(scenarios, checkpoints, config.samples, config.seed)
        paths = write_report(data, config.output_dir)
    except (SessganCoreError, SessganGenError, ValueError, OSError) as err:
        print(f'report: error: {err}', file=sys.stderr)
        return 1
    print(tpkl_markdown(data))
    print(uniqueness_markdown(data))
    print('report: wrote ' + ', '.join(str(path) for path in paths))
    return 0


if __name__ == '__main__':
    sys.exit(main())
