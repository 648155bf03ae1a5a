"""`ros2 run sessgan_evolver compare`: every search method side by side at equal budget.

Runs SESS-GAN and the baselines (random, grid_ga, cellular_automaton, latent) on one scenario
and controller, in process (or, with --external, on the simulators and stack already running
under /w0, /w1, ...), once per search seed; confirms and counts distinct faults,
evaluates the final generators on fresh seeds and writes <output-dir>/report.md, compare.png,
failing_maps.png and CSV files (sessgan_evolver.comparison says how everything is counted).
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path

import torch

from sessgan_core.config_cli import cli, parse_valid_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command
from sessgan_evolver.comparison import CompareConfig, run_comparison
from sessgan_evolver.errors import SessganEvolverError, usage_errors
from sessgan_evolver.regression_suite import SUITE_FILE, suite_line, write_suite_of_bags_below
from sessgan_gen.errors import SessganGenError


@dataclass(frozen=True)
class CompareCommand(CompareConfig):
    """The ``compare`` command's options: what it compares (CompareConfig) and where the
    report goes."""

    output_dir: Path | None = field(default=None, metadata=cli(old=['--output']))
    """Report folder (default: runs/compare-<scenario>-<controller>)."""

    def comparison(self) -> CompareConfig:
        """The settings of the comparison itself, without where its report goes."""
        return CompareConfig(**{setting.name: getattr(self, setting.name)
                                for setting in fields(CompareConfig)})


def parse_args(argv: Sequence[str]) -> CompareCommand:
    """The validated options; a usage error exits 2 naming the option."""
    return parse_valid_config(CompareCommand, argv, 'ros2 run sessgan_evolver compare',
                              __doc__ or '', usage_errors())


def main(argv: Sequence[str] | None = None) -> int:
    """Exit status: 0 done, 1 the comparison failed, 2 bad options (nothing written), 130
    interrupted."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    return run_command(lambda: compare(arguments))


def compare(arguments: list[str]) -> int:
    args = parse_args(arguments)
    torch.set_num_threads(1)
    config = args.comparison()
    output = args.output_dir or Path('runs') / f'compare-{config.scenario}-' \
        f'{config.controller or "default"}'

    def log(message: str) -> None:
        print(f'[compare] {message}', file=sys.stderr, flush=True)

    command = 'ros2 run sessgan_evolver compare ' + shlex.join(arguments)
    # Usage errors (exit 2, nothing written) before the work, failures of it (exit 1).
    if (output / 'report.md').exists():
        print(f'error: {output} holds a comparison already: choose another --output-dir',
              file=sys.stderr)
        return 2
    try:
        result = run_comparison(config, output, command, log)
    except (SessganEvolverError, SessganCoreError, SessganGenError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        log('interrupted')
        return INTERRUPTED_STATUS
    print(f'report: {result.report_path}')
    suite = write_suite_of_bags_below(output / SUITE_FILE, output.name, output / 'faults',
                                      {'source': 'compare: confirmed distinct faults'})
    if suite is not None:
        print(suite_line(suite, config.external))
    return 0


if __name__ == '__main__':
    sys.exit(main())
