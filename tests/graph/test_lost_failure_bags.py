"""A worker that cannot write a failure bag (a full disk) says why in its result's bag_error;
nothing half-written stays behind. Marked ``graph``: the worker's modules need the built
workspace's message types, though no node runs."""

from __future__ import annotations

import errno

import pytest

pytestmark = pytest.mark.graph


class Log:
    def __init__(self) -> None:
        self.errors: list[str] = []

    def error(self, message: str) -> None:
        self.errors.append(message)

    def info(self, message: str) -> None:
        pass


def test_a_bag_lost_to_a_full_disk_is_reported_with_its_reason(ros_workspace, tmp_path,
                                                                monkeypatch):
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment
    from sessgan_sim import bag_recording
    from sessgan_sim.episode import Episode, EpisodeConfig
    from sessgan_sim.simulator_settings import SimulatorSettings
    from sessgan_sim.worker.failure_bags import EpisodeFacts, write_failure_bag
    from sessgan_sim.worker.topics import Recording

    real = bag_recording.write_map_server

    def full(*args, **kwargs):
        real(*args, **kwargs)  # part of the bag is on disk already
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(bag_recording, 'write_map_server', full)
    environment = make_environment(load_example_map('factory').cells, 'factory', 'example')
    with Episode() as episode:
        episode.reset(environment, EpisodeConfig(seed=1, time_limit=1.0))
        metrics = episode.metrics()
        config = episode.config
    log = Log()
    settings = SimulatorSettings()
    path, error = write_failure_bag(
        str(tmp_path / 'bags'), environment, config, metrics, Recording(),
        EpisodeFacts(seed=1, controller='c', namespace='/w0', sim_time_origin_ns=0,
                     settings=settings), log)
    assert path == ''
    assert 'No space left on device' in error and "'example'" in error
    assert log.errors == [error]
    assert list((tmp_path / 'bags').iterdir()) == []  # no staging directory, no half bag
