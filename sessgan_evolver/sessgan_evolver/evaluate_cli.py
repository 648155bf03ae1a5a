"""`ros2 run sessgan_evolver evaluate`: a generator's failure rate on fresh seeds.

Samples --fresh-episodes maps from each generator given (the shipped checkpoint, a campaign's best
member or final population, your own checkpoints, the cellular-automaton baseline) with seeds
no campaign used (--run and --exclude-run name the campaigns; their seeds are read from
their metrics and skipped), runs each map once with the built-in controller in this process
(lockstep; with --external: on the simulators and stack already running under /w0, /w1, ...,
as ``campaign --external``) and writes <output>/summary.md, summary.csv (one row per generator) and
episodes.csv (one row per map): valid maps, failure rate, collisions, risk, TPKL to the
example map, uniqueness, distinct faults. --max-fault-records N keeps the first N confirmed
distinct faults of each generator as a bag with a picture.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import torch

from sessgan_core.config_cli import add_old_spelling
from sessgan_core.environment import MAX_ROBOTS
from sessgan_core.errors import SessganCoreError
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import DEFAULT_DWELL_TIME, MissionSpec
from sessgan_core.progress import ProgressPrinter
from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command
from sessgan_core.scenarios import get_scenario
from sessgan_evolver.campaign import check_controller
from sessgan_evolver.errors import FreshSeedError, SessganEvolverError
from sessgan_evolver.fault_records import confirm_faults
from sessgan_evolver.faults import FaultRule
from sessgan_evolver.fresh_seed import (
    EPISODE_COLUMNS,
    AutomatonSource,
    MapSource,
    PyramidSource,
    campaign_sources,
    check_disjoint,
    episode_rows,
    evaluate_source,
    fresh_seed_plan,
    open_run,
    summary_rows,
    summary_table,
    used_seeds,
    write_csv,
)
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.regression_suite import SUITE_FILE, write_suite_of_bags_below
from sessgan_evolver.worker_episodes import external_record_subdirectory, worker_evaluator
from sessgan_gen.checkpoint import incomplete_warning
from sessgan_gen.errors import SessganGenError
from sessgan_sim.episode import check_time_limit
from sessgan_sim.errors import InvalidConfigError


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='ros2 run sessgan_evolver evaluate',
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenario', default='',
                        help="scenario (default: the --run's, else factory)")
    parser.add_argument('--run', type=Path, action='append', default=[],
                        help='a campaign run directory (runs/<run>) to evaluate; repeatable')
    parser.add_argument('--member', default='best',
                        help="which of a run's last population: best, final (every member) or "
                             'a member index')
    parser.add_argument('--checkpoint', type=Path, action='append', default=[],
                        help='a generator checkpoint (.pt) to evaluate; repeatable')
    parser.add_argument('--shipped', action='store_true',
                        help="also evaluate the scenario's shipped generator (the default "
                             'when no generator is given)')
    parser.add_argument('--cellular-automaton', action='store_true',
                        help='also evaluate the non-learned cellular-automaton generator')
    parser.add_argument('--exclude-run', type=Path, action='append', default=[],
                        help='a further run whose seeds must not be used; repeatable')
    parser.add_argument('--width', type=int, default=0,
                        help='map width in cells (default 0: the size of the map each '
                             "generator learned, a campaign's own size for --run)")
    parser.add_argument('--height', type=int, default=0,
                        help='map height in cells (default 0: as --width)')
    parser.add_argument('--fresh-episodes', dest='episodes', type=int, default=30,
                        help='fresh maps per generator')
    add_old_spelling(parser, '--episodes', 'episodes', type=int)
    parser.add_argument('--evaluation-seed', dest='seed', type=int, default=1000,
                        help='seed of the fresh seeds')
    add_old_spelling(parser, '--seed', 'seed', type=int)
    parser.add_argument('--controller', default='',
                        help="built-in controller (default: the scenario's)")
    parser.add_argument('--time-limit', type=float, default=0.0,
                        help="episode time limit, sim s (default: the scenario's)")
    parser.add_argument('--mission-stations', type=int, default=0,
                        help='pick-up -> place missions: stations drawn before home on every '
                             'fresh map, each leg certified (0..16; default 0: plain start -> '
                             'goal episodes)')
    parser.add_argument('--station-dwell-time', type=float, default=DEFAULT_DWELL_TIME,
                        help='sim seconds the robot stands still at each mission station '
                             f'(default {DEFAULT_DWELL_TIME})')
    parser.add_argument('--robots', type=int, default=1,
                        help='robots under test on every fresh map (a fleet episode: robots '
                             "r1, r2, ... beside the map's own start and goal, each route "
                             f'certified; 1..{MAX_ROBOTS}; default 1: one robot)')
    parser.add_argument('--external', action='store_true',
                        help='run every episode on the evaluate action servers already running '
                             '(your stack under /w0, /w1, ..., as campaign --external) instead '
                             'of in process; --controller then only names it. Their failure '
                             'bags (in <their bags_root>/external/<output folder name>/) must '
                             'be readable on this machine')
    parser.add_argument('--adaptive-rtf', action='store_true',
                        help='--external, clocked simulators: run an episode that ended '
                             'overloaded (the stack could not keep pace with sim time) again '
                             'at half the real-time factor, halved again on each '
                             'overloaded try (down to 1/16)')
    parser.add_argument('--simulate-invalid', action='store_true',
                        help='also simulate maps without a certified route')
    parser.add_argument('--max-fault-records', dest='fault_records', type=int, default=0,
                        help='confirmed distinct faults per generator kept as bag + PNG '
                             '(-1: every one)')
    add_old_spelling(parser, '--fault-records', 'fault_records', type=int)
    parser.add_argument('--repeats', type=int, default=3,
                        help='re-runs that confirm a fault before it is recorded')
    parser.add_argument('--coarse-cells', type=int, default=FaultRule.coarse_cells,
                        help='fault rule: coarse cell side in map cells')
    parser.add_argument('--context-cells', type=int, default=FaultRule.context_cells,
                        help='fault rule: map cells of context around the coarse cell')
    parser.add_argument('--output-dir', dest='output', type=Path, default=None,
                        help='output folder (default: runs/evaluate-<scenario>-seed<seed>)')
    add_old_spelling(parser, '--output', 'output', type=Path)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error('--fresh-episodes must be >= 1')
    if args.width < 0 or args.height < 0:
        parser.error("--width and --height must be >= 0 (0: the generator's map size)")
    if args.adaptive_rtf and not args.external:
        parser.error('--adaptive-rtf needs --external: in process, episodes run in lockstep')
    return args


def build_sources(args: argparse.Namespace, scenario: str) -> list[MapSource]:
    """The generators to evaluate; the cellular automaton makes maps of the first one's size
    and is measured against its training map."""
    size = (args.height, args.width) if args.height or args.width else None
    sources: list[PyramidSource] = []
    for run_dir in args.run:
        sources += campaign_sources(run_dir, args.member, size)
    for checkpoint in args.checkpoint:
        sources.append(PyramidSource(str(checkpoint), scenario, checkpoint, size))
    if args.shipped or not sources:
        sources.insert(0, PyramidSource('shipped generator', scenario, None, size))
    for source in sources:
        if warning := incomplete_warning(source.metadata, source.label):
            print(f'WARNING: {warning}', file=sys.stderr)
    every: list[MapSource] = list(sources)
    if args.cellular_automaton:
        every.append(AutomatonSource(scenario, reference=sources[0].reference,
                                     size=sources[0].size))
    return every


def check_settings(args: argparse.Namespace, scenario: str) -> None:
    """Raise naming the first option a run cannot work with, before anything is written."""
    try:
        check_time_limit(args.time_limit, '--time-limit')
    except InvalidConfigError as err:
        raise FreshSeedError(str(err)) from err
    check_controller(scenario, args.controller)
    for option, value, least in (('--evaluation-seed', args.seed, 0),
                                 ('--repeats', args.repeats, 0),
                                 ('--max-fault-records', args.fault_records, -1)):
        if value < least:
            raise FreshSeedError(f'{option} must be >= {least}, got {value}')
    FaultRule(args.coarse_cells, args.context_cells).validate()


def open_evaluator(args: argparse.Namespace, scenario: str, mission: MissionSpec,
                   fleet: FleetSpec, output: Path) -> AbstractContextManager[Any]:
    """In process, or with --external on the graph's workers (sessgan_evolver
    .worker_episodes)."""
    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    if args.external:
        return worker_evaluator(
            scenario, external_record_subdirectory(output), output / 'logs', args.controller,
            args.time_limit, mission, fleet, simulate_invalid=args.simulate_invalid, log=log,
            adaptive_rtf=args.adaptive_rtf, collect_into=output / 'worker_bags')
    return InProcessEvaluator(scenario, args.controller, args.time_limit,
                              simulate_invalid=args.simulate_invalid, mission=mission,
                              fleet=fleet, log=log)


def main(argv: Sequence[str] | None = None) -> int:
    arguments = sys.argv[1:] if argv is None else list(argv)
    return run_command(lambda: evaluate(arguments))


def evaluate(arguments: list[str]) -> int:
    args = parse_args(arguments)
    torch.set_num_threads(1)
    try:
        scenario = args.scenario
        for run_dir in args.run:
            run_scenario = str(open_run(run_dir).read_config()['config']['scenario'])
            if scenario and scenario != run_scenario:
                raise SessganEvolverError(f'run {run_dir} is a {run_scenario} campaign, not '
                                          f'{scenario}')
            scenario = run_scenario
        scenario = scenario or 'factory'
        get_scenario(scenario)
        check_settings(args, scenario)
        mission = MissionSpec(args.mission_stations, args.station_dwell_time).validate()
        fleet = FleetSpec(args.robots).validate(mission.stations)
        runs = list(args.run) + list(args.exclude_run)
        map_seeds, sim_seeds = used_seeds(runs)
        plan = fresh_seed_plan(args.seed, args.episodes, map_seeds, sim_seeds)
        check_disjoint(plan, runs)
        sources = build_sources(args, scenario)
    except (SessganEvolverError, SessganCoreError, SessganGenError, OSError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    output = args.output or Path('runs') / f'evaluate-{scenario}-seed{args.seed}'
    output.mkdir(parents=True, exist_ok=True)
    rule = FaultRule(args.coarse_cells, args.context_cells)
    print(f'{len(plan.pairs)} fresh seed pairs (evaluation seed {args.seed}); '
          f'{len(map_seeds)} map and {len(sim_seeds)} simulator seeds of {len(runs)} runs '
          f'excluded, {plan.skipped} drawn seeds skipped', file=sys.stderr)
    summaries, rows = [], []
    progress = ProgressPrinter()
    try:
        with open_evaluator(args, scenario, mission, fleet, output) as evaluator:
            for source in sources:
                progress.start(source.label, len(plan.pairs))
                result = evaluate_source(source, plan, evaluator, rule,
                                         lambda done, _: progress.update(done))
                summaries.append(result.summary)
                rows += episode_rows(result)
                if args.fault_records:
                    safe = ''.join(c if c.isalnum() or c in '-_.' else '_'
                                   for c in source.label)
                    confirm_faults(result.faults, result.records, evaluator, rule,
                                   args.repeats, output / 'faults' / safe, args.fault_records,
                                   {'generator': source.label})
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return INTERRUPTED_STATUS
    except (SessganEvolverError, SessganCoreError, SessganGenError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    table = summary_table(summaries)
    write_csv(output / 'summary.csv', summary_rows(summaries))
    write_csv(output / 'episodes.csv', rows, EPISODE_COLUMNS)
    controller = args.controller or ('external' if args.external
                                     else get_scenario(scenario).controller)
    (output / 'summary.md').write_text(
        f'# Fresh-seed evaluation: {scenario}, {controller}\n\n'
        f'Command: `ros2 run sessgan_evolver evaluate {shlex.join(arguments)}`\n\n'
        f'{len(plan.pairs)} fresh (map, simulator) seed pairs from evaluation seed '
        f'{args.seed}, disjoint from the {len(runs)} runs given, '
        + ('on the external workers' if args.external else 'in process (lockstep)')
        + '; failure rate = valid '
        'failures / valid maps; collisions and risk: means over valid maps.\n\n'
        f'{table}\n', encoding='utf-8')
    print(table)
    print(f'summary: {output / "summary.md"}')
    suite = write_suite_of_bags_below(output / SUITE_FILE, output.name, output / 'faults',
                                      {'source': 'evaluate: confirmed distinct faults',
                                       'controller': controller})
    if suite is not None:
        print(f'regression suite: {suite} (re-run: ros2 run sessgan_evolver suite {suite})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
