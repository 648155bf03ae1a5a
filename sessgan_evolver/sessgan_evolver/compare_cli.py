"""`ros2 run sessgan_evolver compare`: every search method side by side at equal budget.

Runs SESS-GAN and the baselines (random, grid_ga, cellular_automaton, latent) on one scenario
and controller, in process (or, with --external, on the simulators and stack already running
under /w0, /w1, ...), once per search seed; confirms and counts distinct faults,
evaluates the final generators on fresh seeds and writes <output>/report.md, compare.png,
failing_maps.png and CSV files (sessgan_evolver.comparison says how everything is counted).
"""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

import torch

from sessgan_core.config_cli import add_old_spelling, field_docs
from sessgan_core.errors import SessganCoreError
from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command
from sessgan_evolver.comparison import CompareConfig, run_comparison
from sessgan_evolver.errors import CompareError, SessganEvolverError
from sessgan_evolver.regression_suite import SUITE_FILE, write_suite_of_bags_below
from sessgan_gen.errors import SessganGenError


def _int_tuple(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split(',') if part.strip())


def _str_tuple(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(',') if part.strip())


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='ros2 run sessgan_evolver compare',
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    docs = field_docs(CompareConfig)
    defaults = CompareConfig()
    for field in dataclasses.fields(CompareConfig):
        flag = '--' + field.name.replace('_', '-')
        default = getattr(defaults, field.name)
        if field.name == 'methods':
            parser.add_argument(flag, type=_str_tuple, default=default,
                                help=docs.get(field.name, '') + ' Comma-separated.')
        elif field.name == 'search_seeds':
            parser.add_argument(flag, type=_int_tuple, default=default,
                                help=docs.get(field.name, '') + ' Comma-separated.')
        elif isinstance(default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default,
                                help=docs.get(field.name, ''))
        else:
            parser.add_argument(flag, type=type(default), default=default,
                                help=docs.get(field.name, ''))
    parser.add_argument('--output-dir', dest='output', type=Path, default=None,
                        help='report folder (default: runs/compare-<scenario>-<controller>)')
    add_old_spelling(parser, '--output', 'output', type=Path)
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Exit status: 0 done, 1 the comparison failed, 2 bad options (nothing written), 130
    interrupted."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    return run_command(lambda: compare(arguments))


def compare(arguments: list[str]) -> int:
    args = parse_args(arguments)
    torch.set_num_threads(1)
    config = CompareConfig(**{field.name: getattr(args, field.name)
                              for field in dataclasses.fields(CompareConfig)})
    output = args.output or Path('runs') / f'compare-{config.scenario}-' \
        f'{config.controller or "default"}'

    def log(message: str) -> None:
        print(f'[compare] {message}', file=sys.stderr, flush=True)

    command = 'ros2 run sessgan_evolver compare ' + shlex.join(arguments)
    try:  # usage errors (exit 2, nothing written) before the work, failures of it (exit 1)
        config.validate()
        if (output / 'report.md').exists():
            raise CompareError(
                f'{output} holds a comparison already: choose another --output-dir')
    except (SessganEvolverError, SessganCoreError, SessganGenError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
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
        print(f'regression suite: {suite} (re-run: ros2 run sessgan_evolver suite {suite})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
