#!/usr/bin/env python3
"""Benchmark of the ROS-free simulator core: physics and sensors alone, no messaging.

The factory reference episode: the shipped 32x32 factory map (0.5 m cells), the
diff_drive robot, a 360-beam scan every 50 ms tick (lidar at 20 Hz, 20 Hz control),
the scenario's 2 dummy agents, and a scripted wander policy that drives around the
map for the whole time limit (stuck and collision limits off, so every episode
runs its full 60 sim seconds).

It prints, per tick, the time spent in physics (agents, robot dynamics, pybullet
steps, contact checks), sensors (lidar and clearance) and metrics, and the
sim-time / time factor of physics + sensors, for the default (merged boxes, the
analytic numpy lidar and clearance), for the analytic lidar with pybullet's
clearance (``getClosestPoints``), for the pybullet lidar (``rayTestBatch``) and
clearance on the ray-only scan surface (the previous default), on the merged
boxes and on the baseline of one box per cell, and for the analytic sensors with
the lidar at 10 Hz. It also times one 360-beam scan of the analytic lidar against
the pybullet one on each example map (from the same poses), and one
``rayTestBatch`` against a per-beam ``rayTest`` loop.

Times are this thread's CPU time by default (``--clock cpu``): on a shared
machine, wall time also counts the time other processes hold the core.
``--clock wall`` measures wall time. Usage::

    python tests/benchmarks/bench_simulator_core.py [--episodes 3] [--clock cpu|wall]
                                                    [--scan-repeats 5]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[2]
for package in ('sessgan_core', 'sessgan_sim'):
    sys.path.insert(0, str(ROOT / package))

from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_sim.episode import Episode, EpisodeConfig, Observation  # noqa: E402
from sessgan_sim.robots import BodyCommand  # noqa: E402
from sessgan_sim.sensors import ClearanceSensor, Lidar, LidarConfig, RayCaster  # noqa: E402
from sessgan_sim.world import SCAN_RAY_MASK, WorldStyle  # noqa: E402

CLOCKS: dict[str, Callable[[], float]] = {'cpu': time.thread_time, 'wall': time.perf_counter}


def wander(observation: Observation) -> BodyCommand:
    """A scripted policy that keeps driving: ahead when clear, turning away from walls."""
    info = observation.lidar
    ranges = np.where(np.isfinite(observation.scan), observation.scan, info.range_max)
    angles = info.angles()
    front = ranges[np.abs(angles) < 0.5].min()
    left = ranges[(angles > 0.5) & (angles < 1.6)].mean()
    right = ranges[(angles < -0.5) & (angles > -1.6)].mean()
    if front < 0.6:
        return BodyCommand(0.0, 0.0, 1.5 if left >= right else -1.5)
    turn = float(np.clip(1.5 * (left - right) / (left + right), -1.0, 1.0))
    return BodyCommand(min(0.8, float(front) - 0.4), 0.0, turn)


@dataclass
class Figures:
    label: str
    ticks: int
    physics: float
    sensors: float
    metrics: float
    sim_time: float
    collisions: int

    @property
    def core(self) -> float:
        """Physics and sensors."""
        return self.physics + self.sensors

    def per_tick_us(self, seconds: float) -> float:
        return seconds / self.ticks * 1e6


@dataclass(frozen=True)
class Variant:
    """One way of simulating the reference episode."""

    label: str
    style: WorldStyle = WorldStyle()
    lidar_rate_hz: float = 20.0
    caster: RayCaster = RayCaster.ANALYTIC
    analytic_clearance: bool = True


def run_episode(episode: Episode, environment: Environment, variant: Variant, seed: int,
                totals: Figures) -> None:
    """Run the reference episode once with ``seed``; add its profile to ``totals``."""
    config = EpisodeConfig(seed=seed, stuck_timeout=0.0, collision_limit=0, world=variant.style,
                           lidar=LidarConfig(rate_hz=variant.lidar_rate_hz,
                                             caster=variant.caster))
    observation = episode.reset(environment, config)
    if not variant.analytic_clearance:
        # The episode has no switch for it: swap in pybullet's clearance sensor.
        live = episode._live  # noqa: SLF001 (benchmark reaches into the core)
        assert live is not None
        live.clearance = ClearanceSensor(live.robot.client, live.robot, episode.layout,
                                         live.clearance.range, analytic=False)
    done = episode.done
    while not done:
        observation, done, _ = episode.step(wander(observation))
    profile, metrics = episode.profile, episode.metrics()
    totals.ticks += profile.ticks
    totals.physics += profile.physics
    totals.sensors += profile.sensors
    totals.metrics += profile.metrics
    totals.sim_time += metrics.simulation_time
    totals.collisions += metrics.collisions


def run_variants(variants: list[Variant], episodes: int, clock_name: str) -> list[Figures]:
    """Run the reference episode ``episodes`` times (seeds 0..n-1) per variant, the variants
    taking turns seed by seed so that a change in the machine's load hits them alike; sum
    the profiles."""
    environment = make_environment(load_example_map('factory').cells, 'factory',
                                   'factory-reference')
    rows = [Figures(variant.label, 0, 0.0, 0.0, 0.0, 0.0, 0) for variant in variants]
    simulations = [Episode(clock=CLOCKS[clock_name]).open() for _ in variants]
    try:
        for seed in range(episodes):
            for variant, episode, totals in zip(variants, simulations, rows, strict=True):
                run_episode(episode, environment, variant, seed, totals)
    finally:
        for episode in simulations:
            episode.close()
    return rows


def time_scan_casts(clock_name: str, repeats: int = 200) -> tuple[float, float]:
    """Seconds per 360-beam scan in the reference map: one rayTestBatch vs a rayTest loop."""
    clock = CLOCKS[clock_name]
    environment = make_environment(load_example_map('factory').cells, 'factory', 'rays')
    with Episode() as episode:
        episode.reset(environment, EpisodeConfig())
        client = episode.robot.client
        x, y = episode.robot.position
        height = episode.robot.sensor_height
        angles = episode.lidar_info.angles()
        starts = [[x, y, height]] * len(angles)
        ends = np.stack([x + 10 * np.cos(angles), y + 10 * np.sin(angles),
                         np.full(len(angles), height)], axis=1).tolist()
        started = clock()
        for _ in range(repeats):
            p.rayTestBatch(starts, ends, numThreads=1, collisionFilterMask=SCAN_RAY_MASK,
                           physicsClientId=client)
        batch = (clock() - started) / repeats
        started = clock()
        for _ in range(repeats // 10):
            for start, end in zip(starts, ends, strict=True):
                p.rayTest(start, end, collisionFilterMask=SCAN_RAY_MASK,
                          physicsClientId=client)
        loop = (clock() - started) / (repeats // 10)
    return batch, loop


def time_lidars(scenario: str, clock_name: str, repeats: int, poses: int = 100
                ) -> tuple[float, float]:
    """Median seconds per scan (of ``repeats`` runs over the same ``poses`` random poses in
    the free cells of the scenario's example map, with its robot and agents) of the analytic
    lidar and of the pybullet one. Each run scans with one lidar only: a pybullet scan
    evicts much of the analytic lidar's working set from the caches, and a scan right
    after it would take up to twice as long."""
    clock = CLOCKS[clock_name]
    environment = make_environment(load_example_map(scenario).cells, scenario, scenario)
    with Episode() as episode:
        episode.reset(environment, EpisodeConfig())
        robot = episode.robot
        lidars = [Lidar(LidarConfig(caster=caster), np.random.default_rng(0))
                  for caster in (RayCaster.ANALYTIC, RayCaster.PYBULLET)]
        for lidar in lidars:
            lidar.attach(robot.client, robot, episode.layout, episode.agents)
        rng = np.random.default_rng(0)
        free = np.argwhere(np.isin(environment.occupancy, robot.passable_values))
        cells = free[rng.integers(0, len(free), poses)]
        points = (cells[:, ::-1] + rng.random((poses, 2))) * environment.resolution
        yaws = rng.uniform(-math.pi, math.pi, poses)
        runs: list[list[float]] = [[], []]
        for _ in range(repeats):
            for index, lidar in enumerate(lidars):
                spent = 0.0
                for (x, y), yaw in zip(points.tolist(), yaws.tolist(), strict=True):
                    # The flyer at its traffic altitude (ground robots: their ride height).
                    p.resetBasePositionAndOrientation(
                        robot.body_id, [x, y, robot.traffic_height],
                        p.getQuaternionFromEuler([0.0, 0.0, yaw]), physicsClientId=robot.client)
                    robot.sync()
                    started = clock()
                    lidar.scan()
                    spent += clock() - started
                runs[index].append(spent / poses)
    return statistics.median(runs[0]), statistics.median(runs[1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--episodes', type=int, default=3,
                        help='reference episodes (60 sim seconds each) per world variant')
    parser.add_argument('--clock', choices=sorted(CLOCKS), default='cpu',
                        help="cpu: this thread's CPU time; wall: wall-clock time")
    parser.add_argument('--scan-repeats', type=int, default=5,
                        help='runs of the per-scan timings (their median is printed)')
    args = parser.parse_args(argv)

    print(f'machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, '
          f'load average {os.getloadavg()[0]:.2f}; python {platform.python_version()}; '
          f'clock: {args.clock}')
    config = EpisodeConfig()
    print(f'reference episode: factory 32x32 @ 0.5 m, diff_drive, {config.lidar.beams} beams '
          f'@ {config.lidar.rate_hz:g} Hz, control {config.control_rate_hz:g} Hz, physics '
          f'{config.physics_rate_hz:g} Hz ({config.physics_steps_per_tick} steps/tick), '
          f'2 agents, {args.episodes} x 60 s sim')
    pybullet = RayCaster.PYBULLET
    rows = run_variants([
        Variant('analytic sensors (default)'),
        Variant('analytic lidar, pyb. clearance', analytic_clearance=False),
        Variant('pybullet sensors, scan surface', caster=pybullet, analytic_clearance=False),
        Variant('pybullet sensors, merged boxes', WorldStyle(scan_surface=False),
                caster=pybullet, analytic_clearance=False),
        Variant('pybullet sensors, box per cell',
                WorldStyle(merge_obstacles=False, scan_surface=False), caster=pybullet,
                analytic_clearance=False),
        Variant('analytic sensors, lidar 10 Hz', lidar_rate_hz=10.0),
    ], args.episodes, args.clock)
    print(f'{"sensors, world":<30} {"physics":>8} {"sensors":>8} {"metrics":>8} {"core":>8} '
          f'{"factor":>8} {"+metrics":>8}')
    print(f'{"":<30} {"us/tick":>8} {"us/tick":>8} {"us/tick":>8} {"us/tick":>8} '
          f'{"sim/" + args.clock:>8} {"factor":>8}')
    for row in rows:
        factor = row.sim_time / row.core if row.core > 0 else math.inf
        with_metrics = row.sim_time / (row.core + row.metrics)
        print(f'{row.label:<30} {row.per_tick_us(row.physics):8.1f} '
              f'{row.per_tick_us(row.sensors):8.1f} {row.per_tick_us(row.metrics):8.1f} '
              f'{row.per_tick_us(row.core):8.1f} {factor:7.0f}x {with_metrics:7.0f}x')
    analytic, lidar_only, surface, boxes, baseline = rows[:5]
    saved = lidar_only.per_tick_us(lidar_only.sensors) - analytic.per_tick_us(analytic.sensors)
    print(f'analytic sensors vs pybullet sensors on the scan surface: core '
          f'{surface.core / analytic.core:.2f}x faster, sensors '
          f'{surface.sensors / analytic.sensors:.2f}x; the analytic clearance alone saves '
          f'{saved:.1f} us/tick')
    print(f'pybullet sensors, scan surface vs box per cell: core '
          f'{baseline.core / surface.core:.2f}x faster, sensors '
          f'{baseline.sensors / surface.sensors:.2f}x, physics '
          f'{baseline.physics / surface.physics:.2f}x')
    print(f'pybullet sensors, scan surface vs rays on the merged boxes: sensors '
          f'{boxes.sensors / surface.sensors:.2f}x faster')
    print(f'one 360-beam scan (Lidar.scan, noise included), median of {args.scan_repeats} '
          f'runs over 100 random free poses:')
    for scenario in ('factory', 'drone', 'racetrack'):
        exact, bullet = time_lidars(scenario, args.clock, args.scan_repeats)
        print(f'  {scenario:<10} analytic {exact * 1e6:6.1f} us, pybullet {bullet * 1e6:6.1f} '
              f'us ({bullet / exact:.1f}x)')
    batch, loop = time_scan_casts(args.clock)
    print(f'one 360-beam scan: rayTestBatch {batch * 1e6:.0f} us, per-beam rayTest loop '
          f'{loop * 1e6:.0f} us ({loop / batch:.1f}x)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
