"""The failure bag of an episode: its messages, map and everything needed to re-simulate it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sessgan_core.fleet import fleet_to_json
from sessgan_sim.bag_recording import (
    BagWriteError,
    episode_bag_directory,
    remove_stale_staging_directories,
    write_episode_bag,
)
from sessgan_sim.simulator_settings import SimulatorSettings, episode_config_record
from sessgan_sim.worker.topics import Recording


@dataclass(frozen=True)
class EpisodeFacts:
    """What episode.json says about the episode besides its metrics."""

    seed: int
    """The episode's seed (sensor noise, agents)."""
    controller: str
    """Name of the controller under test (as the evaluate client gave it)."""
    namespace: str
    """The worker's namespace (topics in the bag are recorded under it)."""
    sim_time_origin_ns: int
    """Sim time of the episode's first tick on the worker's clock."""
    settings: SimulatorSettings
    """Every parameter of the worker that ran it."""


def write_failure_bag(record_directory: str | Path, environment, config, metrics,
                      recording: Recording, facts: EpisodeFacts, log) -> tuple[str, str]:
    """Write ``<record_directory>/<environment id>/``; returns (its path, ''), or ('', why)
    when it could not be written (a full disk, ...: the reason also goes to ``log.error``,
    and the client gets it as the result's bag_error). ``config``: the resolved episode
    config."""
    metadata = {
        'environment_id': environment.id, 'scenario': environment.scenario,
        'seed': environment.seed, 'episode_seed': int(facts.seed),
        'generation': environment.generation, 'member': environment.member,
        'controller': facts.controller, 'metrics': metrics.to_dict(),
        'robot': config.robot, 'time_limit': config.time_limit,
        'start': [environment.start.x, environment.start.y, environment.start.yaw],
        'goal': [environment.goal.x, environment.goal.y, environment.goal.yaw],
        'feasible': environment.feasible, 'route_length': environment.route_length,
        'route_min_clearance': environment.route_min_clearance, 'namespace': facts.namespace,
        'stations': [[pose.x, pose.y, pose.yaw] for pose in environment.stations],
        'dwell_time': environment.dwell_time, 'fleet': fleet_to_json(environment.fleet),
        'mode': facts.settings.mode,
        'sim_time_origin': facts.sim_time_origin_ns / 1e9,
        'sim_time_origin_ns': int(facts.sim_time_origin_ns),
        'simulator': facts.settings.to_dict(),
        'episode_config': episode_config_record(config),
    }
    try:
        path = write_episode_bag(
            episode_bag_directory(record_directory, environment.id), recording.records(),
            metadata, environment.occupancy, environment.resolution, environment.origin,
            storage=facts.settings.bag_storage, overwrite=True)
    except (BagWriteError, OSError, ValueError) as err:
        reason = f'cannot write the failure bag of {environment.id!r} in {record_directory}: {err}'
        log.error(reason)
        return '', reason
    log.info(f'failure bag written: {path}')
    return str(path), ''


def remove_partial_bags(record_directory: str | Path, log) -> None:
    """Remove the ``<id>.tmp-<pid>`` staging directories a killed worker left behind in
    ``record_directory``: only those whose marker proves them a dead writer's of this host
    (``remove_stale_staging_directories``; missing directories are fine)."""
    if not str(record_directory) or not Path(record_directory).is_dir():
        return
    try:
        removed = remove_stale_staging_directories(record_directory)
    except OSError as err:
        log.warning(f'cannot clean up partial bags in {record_directory}: {err}')
        return
    for path in removed:
        log.info(f'removed a partial bag left by a killed worker: {path}')
