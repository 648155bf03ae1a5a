#!/usr/bin/env python3
"""Benchmark of the built-in controllers: every scenario x controller on the same fresh maps.

Not a test (pytest does not collect it); run it and read the figures::

    nice -n 10 python tests/benchmarks/bench_controllers.py                 # 100 maps each
    nice -n 10 python tests/benchmarks/bench_controllers.py --episodes 20 --scenario factory
    nice -n 10 python tests/benchmarks/bench_controllers.py --controller nearness_diagram \\
        --scenario factory --failures

For each scenario, maps are sampled from the shipped generator (generation 0) with seeds from
``--first-seed`` on (1000000: used by no tuning and no other benchmark) until ``--episodes``
of them are valid tests (``feasible``); every controller of the scenario drives one episode
per valid map, in-process on the simulator core (sessgan_sim's Episode, lockstep, the
scenario's defaults: dummy agents, time limit, 360-beam lidar, 20 Hz), with the map seed as
the episode seed. A controller that plans on the map gets it first (``set_map``), as the
node does from the ``map`` topic; once it reports the goal reached it is sent a stop, as the
node sends. Same seeds, same figures.

Per scenario x controller it prints a markdown table:

* success: goal reached with no fault collision (sessgan_sim.metrics), in % of episodes;
* fault collisions per episode (contacts the robot caused), and the % of episodes with a
  fault contact on a wall / obstacle (static) and with the robot moving into an agent;
* stuck / timeout: the goal not reached, in % of episodes (collision limit separately);
* the median speed of the robot when its fault contacts began (fast: a braking fault);
* mean simulation time of all episodes and of the successful ones;

and with ``--png PATH`` a bar chart of the success rates. ``--failures`` lists every failed
episode's map seed, outcome and contacts (to re-run one: ``--first-seed SEED --episodes 1``).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_gen', 'sessgan_sim', 'controllers'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_controllers.controller_interface import (  # noqa: E402
    STOP,
    Goal,
    MapData,
    accepts_map,
    observed,
)
from sessgan_controllers.registry import CONTROLLERS, ControllerSpec  # noqa: E402
from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.progress import ProgressPrinter, format_duration  # noqa: E402
from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_gen.environment_sampler import EnvironmentSampler  # noqa: E402
from sessgan_sim.episode import Episode, EpisodeConfig  # noqa: E402
from sessgan_sim.metrics import EpisodeMetrics, Outcome  # noqa: E402

FIRST_SEED = 1_000_000
"""Map seeds from here on are fresh: tuning used 800000-800199 (reference navigator) and
900000-900099 (the paper's controllers); bench_valid_tests.py uses 700000 on."""

SAMPLE_BATCH = 25

SCENARIO_CONTROLLERS: dict[str, tuple[str, ...]] = {
    'factory': ('nearness_diagram', 'tricycle_nearness_diagram', 'reference_navigator'),
    'drone': ('velocity_projection', 'reference_navigator'),
    'racetrack': ('race_controller', 'reference_navigator'),
}
"""The built-in controllers benchmarked in each scenario (those registered are run)."""


@dataclass(frozen=True)
class EpisodeResult:
    """What one episode of one controller on one map gave."""

    seed: int
    """Map seed (also the episode seed)."""
    outcome: str
    fault_collisions: int
    static_collisions: int
    robot_into_agent_collisions: int
    simulation_time: float
    contacts: str
    """Each contact event as 'kind@time', for --failures."""
    fault_contact_speeds: tuple[float, ...] = ()
    """m/s, the robot's speed at the start of the tick in which each fault contact began."""

    @property
    def success(self) -> bool:
        return self.outcome == Outcome.GOAL_REACHED and self.fault_collisions == 0

    @classmethod
    def of(cls, seed: int, metrics: EpisodeMetrics,
           fault_contact_speeds: Sequence[float]) -> EpisodeResult:
        contacts = ' '.join(f'{event.kind.value}@{event.time:.1f}s'
                            for event in metrics.contacts)
        return cls(seed, str(metrics.outcome), metrics.fault_collisions,
                   metrics.static_collisions, metrics.robot_into_agent_collisions,
                   metrics.simulation_time, contacts, tuple(fault_contact_speeds))


@dataclass(frozen=True)
class Row:
    """The figures of one scenario x controller."""

    scenario: str
    controller: str
    robot: str
    results: tuple[EpisodeResult, ...]
    seconds: float
    """Wall-clock seconds the episodes took."""

    def share(self, predicate) -> float:
        """% of episodes for which ``predicate(result)`` holds."""
        return 100.0 * sum(1 for result in self.results if predicate(result)) / len(self.results)

    @property
    def success(self) -> float:
        return self.share(lambda result: result.success)

    def markdown(self) -> str:
        results = self.results
        successes = [result.simulation_time for result in results if result.success]
        mean_success = f'{statistics.fmean(successes):.1f}' if successes else '-'
        speeds = [speed for result in results for speed in result.fault_contact_speeds]
        contact_speed = f'{statistics.median(speeds):.1f}' if speeds else '-'
        return (
            f'| {self.scenario} | {self.controller} ({self.robot}) | {len(results)} | '
            f'**{self.success:.0f} %** | '
            f'{statistics.fmean(r.fault_collisions for r in results):.2f} | '
            f'{self.share(lambda r: r.static_collisions > 0):.0f} % | '
            f'{self.share(lambda r: r.robot_into_agent_collisions > 0):.0f} % | '
            f'{self.share(lambda r: r.outcome in (Outcome.STUCK, Outcome.TIMEOUT)):.0f} % | '
            f'{self.share(lambda r: r.outcome == Outcome.COLLISION_LIMIT):.0f} % | '
            f'{contact_speed} | '
            f'{statistics.fmean(r.simulation_time for r in results):.1f} / {mean_success} |')


HEADER = ('| scenario | controller (robot) | episodes | success | fault collisions / episode '
          '| episodes with a static fault contact | with the robot moving into an agent '
          '| stuck / timeout | collision limit | median speed at fault contacts m/s '
          '| mean sim time s (all / successes) |\n'
          '|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|')


def valid_maps(scenario: str, count: int, first_seed: int,
               progress: ProgressPrinter) -> list[Environment]:
    """The first ``count`` valid tests among the shipped generator's maps from
    ``first_seed`` on."""
    sampler = EnvironmentSampler()
    maps: list[Environment] = []
    seed = first_seed
    progress.start(f'{scenario}: sampling valid maps', count)
    while len(maps) < count:
        batch = sampler.sample(list(range(seed, seed + SAMPLE_BATCH)), scenario=scenario)
        maps += [environment for environment in batch if environment.feasible]
        seed += SAMPLE_BATCH
        progress.update(min(len(maps), count))
    return maps[:count]


def run_episode(spec: ControllerSpec, robot: str, environment: Environment,
                overrides: dict[str, object]) -> EpisodeResult:
    """One lockstep episode of a fresh controller on ``environment``; ``overrides`` are
    parameters set where the controller has them."""
    fields = {item.name: item.default for item in dataclasses.fields(spec.config_type)}
    values = {name: type(fields[name])(value) for name, value in overrides.items()
              if name in fields}
    if 'robot' in fields:
        values['robot'] = robot
    controller = spec.make(**values)
    if accepts_map(controller):
        controller.set_map(MapData.of(environment))
    goal = Goal(environment.goal.x, environment.goal.y)
    with Episode() as episode:
        config = EpisodeConfig(robot=robot, seed=int(environment.seed))
        observation = episode.reset(environment, config)
        done = episode.done
        contacts = 0
        speeds: list[float] = []
        while not done:
            scan, state = observed(observation)
            command = (STOP if controller.goal_reached(state, goal)
                       else controller.compute_command(scan, state, goal))
            observation, done, _ = episode.step(command.values())
            events = episode.metrics().contacts
            speeds += [state.speed for event in events[contacts:] if event.fault]
            contacts = len(events)
        return EpisodeResult.of(int(environment.seed), episode.metrics(), speeds)


def benchmark(scenario: str, controller: str, maps: Sequence[Environment],
              overrides: dict[str, object], progress: ProgressPrinter) -> Row:
    spec = CONTROLLERS[controller]
    robot = spec.robot_in(get_scenario(scenario).robot)  # the tricycle's own in the factory
    results = []
    started = time.perf_counter()
    progress.start(f'{scenario}: {controller}', len(maps))
    for environment in maps:
        results.append(run_episode(spec, robot, environment, overrides))
        successes = sum(1 for result in results if result.success)
        progress.update(len(results), f'success {successes}/{len(results)}')
    return Row(scenario, controller, robot, tuple(results), time.perf_counter() - started)


def bar_chart(rows: Sequence[Row], path: Path) -> None:
    """Success rate of every scenario x controller as a horizontal bar chart (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    labels = [f'{row.scenario}: {row.controller}' for row in rows][::-1]
    values = [row.success for row in rows][::-1]
    figure, axes = plt.subplots(figsize=(7.0, 0.45 * len(rows) + 1.4))
    axes.barh(labels, values, color='tab:blue')
    axes.axvline(60.0, color='tab:red', linestyle='--', linewidth=1.0,
                 label="60 %: target of the paper's controllers")
    axes.axvline(90.0, color='tab:green', linestyle='--', linewidth=1.0,
                 label='90 %: target of the reference navigator')
    for index, value in enumerate(values):
        axes.text(value + 1.0, index, f'{value:.0f} %', va='center', fontsize=8)
    axes.set_xlim(0.0, 110.0)
    axes.set_xlabel(f'success: goal reached, no fault collision (% of {len(rows[0].results)} '
                    'valid maps)')
    axes.legend(loc='lower center', bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=7,
                frameon=False)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--episodes', type=int, default=100,
                        help='valid maps (episodes per controller) per scenario [100]')
    parser.add_argument('--scenario', action='append', choices=tuple(SCENARIO_CONTROLLERS),
                        help='scenario(s) to run [all three]')
    parser.add_argument('--controller', action='append',
                        help='only these controllers [every built-in one of the scenario]')
    parser.add_argument('--first-seed', type=int, default=FIRST_SEED,
                        help=f'first map seed [{FIRST_SEED}]')
    parser.add_argument('--png', type=Path, help='write a bar chart of the success rates here')
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                        help='a controller parameter, for every controller that has it')
    parser.add_argument('--failures', action='store_true',
                        help="list every failed episode's map seed, outcome and contacts")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error('--episodes must be at least 1')
    unknown = sorted(set(args.controller or ()) - set(CONTROLLERS))
    if unknown:
        parser.error(f'unknown controller(s) {unknown}; known: {sorted(CONTROLLERS)}')
    overrides: dict[str, object] = {}
    for item in args.set:
        name, separator, value = item.partition('=')
        if not separator:
            parser.error(f'--set takes NAME=VALUE, got {item!r}')
        overrides[name] = float(value) if value.lower() not in ('true', 'false') \
            else value.lower() == 'true'
    try:
        import torch
        torch.set_num_threads(1)  # sampling is a small part; leave the other core alone
    except ImportError:
        pass

    progress = ProgressPrinter()
    started = time.perf_counter()
    rows: list[Row] = []
    skipped: list[str] = []
    for scenario in args.scenario or tuple(SCENARIO_CONTROLLERS):
        names = [name for name in SCENARIO_CONTROLLERS[scenario]
                 if args.controller is None or name in args.controller]
        skipped += [f'{scenario}: {name}' for name in names if name not in CONTROLLERS]
        names = [name for name in names if name in CONTROLLERS]
        if not names:
            continue
        maps = valid_maps(scenario, args.episodes, args.first_seed, progress)
        rows += [benchmark(scenario, name, maps, overrides, progress) for name in names]

    print(f'\nControllers on {args.episodes} valid generation-0 maps per scenario (map seeds '
          f'from {args.first_seed}), in-process lockstep, '
          f'{format_duration(time.perf_counter() - started)} in all:\n')
    print(HEADER)
    for row in rows:
        print(row.markdown())
    if skipped:
        print(f'\nNot registered here (skipped): {", ".join(skipped)}')
    if args.failures:
        for row in rows:
            failed = [result for result in row.results if not result.success]
            print(f'\n{row.scenario} / {row.controller}: {len(failed)} failures')
            for result in failed:
                print(f'  seed {result.seed}: {result.outcome}, {result.fault_collisions} '
                      f'fault collision(s), {result.simulation_time:.1f} s; {result.contacts}')
    if args.png and rows:
        bar_chart(rows, args.png)
        print(f'\nBar chart: {args.png}')


if __name__ == '__main__':
    main()
