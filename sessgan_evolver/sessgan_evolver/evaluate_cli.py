"""`ros2 run sessgan_evolver evaluate`: a generator's failure rate on fresh seeds.

Samples --fresh-episodes maps from each generator given (the shipped checkpoint, a
campaign's best member or final population, your own checkpoints, the cellular-automaton
baseline) with seeds no campaign used (--run and --exclude-run name the campaigns under
--runs-root, --run-dir and --exclude-run-dir give their folders; their seeds are read from
their metrics and skipped), runs each map once with the built-in controller in this process
(lockstep; with --external: on the simulators and stack already running under /w0, /w1, ...,
as ``campaign --external``) and writes <output-dir>/summary.md, summary.csv (one row per
generator) and episodes.csv (one row per map): valid maps, failure rate, collisions, risk,
TPKL to the map the generator learned (the scenario's example map for the shipped
checkpoints), uniqueness (n/a for a patch larger than the maps), distinct faults,
harness re-runs (episodes the test harness ended and ran again: never results).
--max-fault-records N keeps the first N confirmed distinct faults of each generator as a bag
with a picture.
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from sessgan_core.config_cli import cli, parse_valid_config
from sessgan_core.errors import SessganCoreError
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import DEFAULT_DWELL_TIME, MissionSpec
from sessgan_core.progress import ProgressPrinter
from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command
from sessgan_core.scenarios import get_scenario
from sessgan_evolver.campaign import check_controller
from sessgan_evolver.errors import FreshSeedError, SessganEvolverError, usage_errors
from sessgan_evolver.fault_records import confirm_faults
from sessgan_evolver.faults import FaultEntry, FaultRule
from sessgan_evolver.fresh_seed import (
    EPISODE_COLUMNS,
    AutomatonSource,
    FreshSeedSummary,
    MapSource,
    PyramidSource,
    campaign_sources,
    check_disjoint,
    episode_rows,
    evaluate_source,
    fresh_seed_plan,
    harness_reruns_of,
    open_run,
    summary_rows,
    summary_table,
    used_seeds,
    write_csv,
)
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.regression_suite import SUITE_FILE, suite_line, write_suite_of_bags_below
from sessgan_evolver.worker_episodes import external_record_subdirectory, worker_evaluator
from sessgan_gen.checkpoint import incomplete_warning
from sessgan_gen.environment_metrics import DEFAULT_TPKL_SIZES
from sessgan_gen.errors import SessganGenError
from sessgan_sim.episode import check_time_limit
from sessgan_sim.errors import InvalidConfigError


@dataclass
class EvaluateConfig:
    """The ``evaluate`` command's options."""

    scenario: str = ''
    """Scenario (default: the --run's, else factory)."""
    run: tuple[str, ...] = ()
    """Campaign runs to evaluate, by name (<runs-root>/<run>, as campaign --run)."""
    run_dir: tuple[Path, ...] = ()
    """Campaign run folders to evaluate, by path."""
    runs_root: Path = Path('runs')
    """Folder of the run folders --run and --exclude-run name (campaign's --runs-root)."""
    member: str = 'best'
    """Which of a run's last population: best, final (every member) or a member index."""
    checkpoint: tuple[Path, ...] = ()
    """Generator checkpoints (.pt) to evaluate."""
    shipped: bool = False
    """Also evaluate the scenario's shipped generator (the default when no generator is
    given)."""
    cellular_automaton: bool = False
    """Also evaluate the non-learned cellular-automaton generator."""
    exclude_run: tuple[str, ...] = ()
    """Further runs, by name under --runs-root, whose seeds must not be used."""
    exclude_run_dir: tuple[Path, ...] = ()
    """Further run folders, by path, whose seeds must not be used."""
    width: int = 0
    """Map width in cells (default 0: the size of the map each generator learned, a
    campaign's own size for --run)."""
    height: int = 0
    """Map height in cells (default 0: as --width)."""
    fresh_episodes: int = field(default=30, metadata=cli(old=['--episodes']))
    """Fresh maps per generator."""
    evaluation_seed: int = field(default=1000, metadata=cli(old=['--seed']))
    """Seed of the fresh seeds."""
    controller: str = ''
    """Built-in controller (default: the scenario's)."""
    time_limit: float = 0.0
    """Episode time limit, sim s (default 0: the scenario's)."""
    mission_stations: int = 0
    """Pick-up -> place missions: stations drawn before home on every fresh map, each leg
    certified (0..16; default 0: plain start -> goal episodes)."""
    station_dwell_time: float = DEFAULT_DWELL_TIME
    """Sim seconds the robot stands still at each mission station."""
    robots: int = 1
    """Robots under test on every fresh map (a fleet episode: robots r1, r2, ... beside the
    map's own start and goal, each route certified; 1..8; default 1: one robot)."""
    external: bool = False
    """Run every episode on the evaluate action servers already running (your stack under
    /w0, /w1, ..., as campaign --external) instead of in process; --controller then only
    names it. Their failure bags (in <their bags_root>/external/<output folder name>/) are
    copied over ROS into <output-dir>/worker_bags/, so the workers may run on other
    machines."""
    adaptive_rtf: bool = False
    """--external, clocked simulators: run an episode that ended overloaded (the stack could
    not keep pace with sim time) again at half the real-time factor, halved again on each
    overloaded try (down to 1/16)."""
    simulate_invalid: bool = False
    """Also simulate maps without a certified route."""
    max_fault_records: int = field(default=0, metadata=cli(old=['--fault-records']))
    """Confirmed distinct faults per generator kept as bag + PNG (-1: every one)."""
    repeats: int = 3
    """Re-runs that confirm a fault before it is recorded."""
    coarse_cells: int = FaultRule.coarse_cells
    """Fault rule: coarse cell side in map cells."""
    context_cells: int = FaultRule.context_cells
    """Fault rule: map cells of context around the coarse cell."""
    output_dir: Path | None = field(default=None, metadata=cli(old=['--output']))
    """Output folder (default: runs/evaluate-<scenario>-seed<evaluation seed>)."""

    def validate(self) -> None:
        """FreshSeedError naming the first option no evaluation can work with (the scenario's
        controller is checked once the scenario is known: :func:`check_controller`)."""
        if self.fresh_episodes < 1:
            raise FreshSeedError(f'--fresh-episodes must be >= 1, got {self.fresh_episodes}')
        if self.width < 0 or self.height < 0:
            raise FreshSeedError("--width and --height must be >= 0 (0: the generator's map "
                                 'size)')
        tile = max(DEFAULT_TPKL_SIZES)
        for option, side in (('--width', self.width), ('--height', self.height)):
            if 0 < side < tile:
                raise FreshSeedError(f'{option} {side}: a map needs at least {tile} cells a '
                                     f'side for its TPKL ({tile}x{tile} tiles; 0: the '
                                     "generator's map size)")
        if self.member != 'best' and not (self.run or self.run_dir):
            raise FreshSeedError(f"--member {self.member} picks a member of a --run's last "
                                 'population: give --run (or --run-dir) with it')
        if self.adaptive_rtf and not self.external:
            raise FreshSeedError('--adaptive-rtf needs --external: in process, episodes run '
                                 'in lockstep')
        try:
            check_time_limit(self.time_limit, '--time-limit')
        except InvalidConfigError as err:
            raise FreshSeedError(str(err)) from err
        for option, value, least in (('--evaluation-seed', self.evaluation_seed, 0),
                                     ('--repeats', self.repeats, 0),
                                     ('--max-fault-records', self.max_fault_records, -1)):
            if value < least:
                raise FreshSeedError(f'{option} must be >= {least}, got {value}')
        FaultRule(self.coarse_cells, self.context_cells).validate()
        self.fleet(self.mission())

    def run_directories(self) -> tuple[list[Path], list[Path]]:
        """The folders of the runs to evaluate and of those only excluded (FreshSeedError
        naming a run that is not there)."""
        def folders(names: Sequence[str], paths: Sequence[Path], option: str) -> list[Path]:
            return [run_directory(name, self.runs_root, option) for name in names] + [
                Path(path) for path in paths]
        return (folders(self.run, self.run_dir, '--run'),
                folders(self.exclude_run, self.exclude_run_dir, '--exclude-run'))

    def mission(self) -> MissionSpec:
        return MissionSpec(self.mission_stations, self.station_dwell_time).validate()

    def fleet(self, mission: MissionSpec) -> FleetSpec:
        return FleetSpec(self.robots).validate(mission.stations)


def run_directory(name: str, runs_root: Path, option: str = '--run') -> Path:
    """The folder of the run ``name`` under ``runs_root``. A path to a run folder is still
    taken (what ``option`` was before it became a name), with a note naming ``option``-dir."""
    folder = runs_root / name
    if len(Path(name).parts) == 1 and not Path(name).is_absolute() and folder.is_dir():
        return folder
    if Path(name).is_dir():
        print(f'note: {option} {name}: {option} takes a run name under --runs-root '
              f'({runs_root}); a run folder goes to {option}-dir', file=sys.stderr)
        return Path(name)
    raise FreshSeedError(f'{option} {name}: no run folder {folder} (--runs-root {runs_root})')


def parse_args(argv: Sequence[str]) -> EvaluateConfig:
    """The validated options; a usage error exits 2 naming the option."""
    return parse_valid_config(EvaluateConfig, argv, 'ros2 run sessgan_evolver evaluate',
                              __doc__ or '', usage_errors())


def build_sources(args: EvaluateConfig, scenario: str,
                  run_dirs: Sequence[Path] = ()) -> list[MapSource]:
    """The generators to evaluate (those of the campaign runs in ``run_dirs`` first); the
    cellular automaton makes maps of the first one's size and is measured against its
    training map."""
    size = (args.height, args.width) if args.height or args.width else None
    sources: list[PyramidSource] = []
    try:
        for run_dir in run_dirs:
            sources += campaign_sources(run_dir, args.member, size)
        for checkpoint in args.checkpoint:
            sources.append(PyramidSource(str(checkpoint), scenario, checkpoint, size))
        if args.shipped or not sources:
            sources.insert(0, PyramidSource('shipped generator', scenario, None, size))
    except FreshSeedError as err:
        if size is not None and 'size' in str(err):
            # The generator's own bounds (its coarsest scale): say which option asked.
            raise FreshSeedError(f'--width {args.width} --height {args.height}: {err}') from err
        raise
    for source in sources:
        if warning := incomplete_warning(source.metadata, source.label):
            print(f'WARNING: {warning}', file=sys.stderr)
    every: list[MapSource] = list(sources)
    if args.cellular_automaton:
        every.append(AutomatonSource(scenario, reference=sources[0].reference,
                                     size=sources[0].size, origin=sources[0].origin))
    return every


def confirmation_line(label: str, faults: Sequence[FaultEntry], repeats: int,
                      kept: Sequence[Path]) -> str:
    """How many of a generator's distinct faults their re-runs confirmed, and where the
    records of the confirmed ones are (an unconfirmed fault gets no record)."""
    confirmed = sum(entry.confirmation is not None and entry.confirmation.confirmed
                    for entry in faults)
    line = (f'{label}: {confirmed} of {len(faults)} distinct faults confirmed ({repeats} '
            f're-runs each showed the same kind at the same place, its coarse cell or a '
            'neighbouring one)')
    if kept:
        return line + f'; {len(kept)} kept as bag + picture in {Path(kept[0]).parent}'
    return line + '; none kept' + (' (only confirmed faults are)' if faults else '')


def harness_paragraph(reruns: int, summaries: Sequence[FreshSeedSummary]) -> str:
    """summary.md's line on the episodes the test harness ended and ran again (0 in process,
    normally; per generator in summary.csv and per episode in episodes.csv)."""
    line = (f'Harness re-runs: {reruns} (episodes the test harness ended, a silent '
            'controller or a dead process, not the controller under test, and ran again; '
            'none of them is a result')
    if reruns:
        line += '; ' + ', '.join(f'{s.generator}: {s.harness_reruns}' for s in summaries
                                 if s.harness_reruns)
        line += '; the `harness_reruns` columns of summary.csv and episodes.csv say where'
    return line + ').'


def open_evaluator(args: EvaluateConfig, scenario: str, mission: MissionSpec,
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
        evaluated, excluded = args.run_directories()
        scenario = args.scenario
        for run_dir in evaluated:
            run_scenario = str(open_run(run_dir).read_config()['config']['scenario'])
            if scenario and scenario != run_scenario:
                raise SessganEvolverError(f'run {run_dir} is a {run_scenario} campaign, not '
                                          f'{scenario}')
            scenario = run_scenario
        scenario = scenario or 'factory'
        get_scenario(scenario)
        check_controller(scenario, args.controller)
        mission = args.mission()
        fleet = args.fleet(mission)
        runs = evaluated + excluded
        map_seeds, sim_seeds = used_seeds(runs)
        plan = fresh_seed_plan(args.evaluation_seed, args.fresh_episodes, map_seeds, sim_seeds)
        check_disjoint(plan, runs)
        sources = build_sources(args, scenario, evaluated)
    except (SessganEvolverError, SessganCoreError, SessganGenError, OSError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    output = args.output_dir or Path('runs') / f'evaluate-{scenario}-seed{args.evaluation_seed}'
    output.mkdir(parents=True, exist_ok=True)
    rule = FaultRule(args.coarse_cells, args.context_cells)
    print(f'{len(plan.pairs)} fresh seed pairs (evaluation seed {args.evaluation_seed}); '
          f'{len(map_seeds)} map and {len(sim_seeds)} simulator seeds of {len(runs)} runs '
          f'excluded, {plan.skipped} drawn seeds skipped', file=sys.stderr)
    summaries, rows, confirmations = [], [], []
    harness_reruns = 0
    progress = ProgressPrinter()
    try:
        with open_evaluator(args, scenario, mission, fleet, output) as evaluator:
            for source in sources:
                progress.start(source.label, len(plan.pairs))
                result = evaluate_source(source, plan, evaluator, rule,
                                         lambda done, _: progress.update(done))
                summaries.append(result.summary)
                rows += episode_rows(result)
                if args.max_fault_records:
                    safe = ''.join(c if c.isalnum() or c in '-_.' else '_'
                                   for c in source.label)
                    reruns_before = harness_reruns_of(evaluator)
                    kept = confirm_faults(result.faults, result.records, evaluator, rule,
                                          args.repeats, output / 'faults' / safe,
                                          args.max_fault_records, {'generator': source.label})
                    result.summary.harness_reruns += harness_reruns_of(evaluator) - reruns_before
                    confirmations.append(confirmation_line(source.label, result.faults,
                                                           args.repeats, kept))
                    print(confirmations[-1], file=sys.stderr)
            harness_reruns = harness_reruns_of(evaluator)
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
        f'{args.evaluation_seed}, disjoint from the {len(runs)} runs given, '
        + ('on the external workers' if args.external else 'in process (lockstep)')
        + '; failure rate = valid '
        'failures / valid maps; collisions and risk: means over valid maps; uniqueness: '
        'mean of the 8x8 and 16x16 patch uniqueness (n/a when the maps are smaller than 16 '
        'cells a side; each size in summary.csv, empty there when n/a).\n\n'
        f'{table}\n\n{harness_paragraph(harness_reruns, summaries)}\n'
        + ''.join(f'\n{line}\n' for line in confirmations), encoding='utf-8')
    print(table)
    if harness_reruns:
        print(f'harness re-runs {harness_reruns} (episodes the harness, not the controller, '
              'ended: run again)')
    print(f'summary: {output / "summary.md"}')
    suite = write_suite_of_bags_below(output / SUITE_FILE, output.name, output / 'faults',
                                      {'source': 'evaluate: confirmed distinct faults',
                                       'controller': controller})
    if suite is not None:
        print(suite_line(suite, args.external))
    return 0


if __name__ == '__main__':
    sys.exit(main())
