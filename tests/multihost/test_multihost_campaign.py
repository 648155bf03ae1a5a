"""A campaign on one host, its workers on two others: hosts made of network namespaces joined
by a bridge (network_namespaces.py), DDS discovery across them by SUBNET multicast
(conftest.dds_environment). Runs as root only; skipped elsewhere with the reason."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

from sessgan_evolver.bag_reading import verify_bag_files
from tests.multihost.conftest import campaign_command, start_worker

pytestmark = pytest.mark.multihost

CAMPAIGN_TIMEOUT = 600.0
EPISODE_LOG = re.compile(r'\]: episode \S+: \w+ after ')


def read_csv(path) -> list[dict]:
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_a_campaign_runs_on_workers_of_two_other_hosts(multihost, tmp_path):
    network, processes = multihost
    workers = [start_worker(network, processes, 'worker_a', '/w0', tmp_path / 'bags_a'),
               start_worker(network, processes, 'worker_b', '/w1', tmp_path / 'bags_b')]
    for process in processes.processes[::2]:
        process.wait_for_output('simulator ready', timeout=120.0)
    campaign = processes.start(campaign_command(network, [
        '--scenario', 'factory', '--generations', '1', '--population', '2',
        '--maps-per-member', '2', '--time-limit', '15', '--seed', '3', '--run', 'spread',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')]),
        name='campaign')
    assert campaign.wait(timeout=CAMPAIGN_TIMEOUT) == 0, campaign.output()[-4000:]
    log = campaign.output()
    for worker in workers:
        assert f'worker found: {worker.namespace}/evaluate' in log, log[-3000:]
    # The campaign started the generator beside itself, in its namespace.
    assert list((tmp_path / 'runs' / 'spread' / 'logs').glob('generator*.log'))
    episodes = read_csv(tmp_path / 'runs' / 'spread' / 'metrics_episodes.csv')
    assert len(episodes) == 4
    # Both remote workers ran episodes: each simulator logs one line per episode.
    ran = [len(EPISODE_LOG.findall(processes.processes[2 * index].output()))
           for index in range(len(workers))]
    assert all(count >= 1 for count in ran) and sum(ran) >= 4, ran

    # Every failure found on a remote worker is in the campaign's own bags/<run>/,
    # byte-identical to what the worker wrote (kept there: --worker-bags keep, the default).
    failures = [row for row in episodes if row['bag_path']]
    assert failures, 'no failure bag: the test checks nothing'
    collected = tmp_path / 'bags' / 'spread'
    assert sorted(path.name for path in collected.iterdir()) == \
        sorted(Path(row['bag_path']).name for row in failures)
    for row in failures:
        assert Path(row['bag_path']) == collected / Path(row['bag_path']).name
        (worker_copy,) = [worker.bags_root / 'spread' / Path(row['bag_path']).name
                          for worker in workers
                          if (worker.bags_root / 'spread' / Path(row['bag_path']).name).is_dir()]
        assert files_of(Path(row['bag_path'])) == files_of(worker_copy)
    assert log.count('collected from /w') == len(failures)
    assert f'failure bags: {collected}' in log

    # It re-simulates, here on the campaign's host, against a worker on another one.
    bag = Path(failures[0]['bag_path'])
    replay = processes.start(network.hosts['campaign'].command(
        ['ros2', 'run', 'sessgan_evolver', 'replay', str(bag), '--resimulate', '--worker',
         '/w0']), name='replay')
    assert replay.wait(timeout=300) == 0, replay.output()[-3000:]

    # --worker-bags remove: the workers keep nothing of a run once it is collected.
    again = processes.start(campaign_command(network, [
        '--scenario', 'factory', '--generations', '1', '--population', '2',
        '--maps-per-member', '1', '--time-limit', '15', '--seed', '4', '--run', 'moved',
        '--worker-bags', 'remove', '--runs-root', str(tmp_path / 'runs'), '--bags-root',
        str(tmp_path / 'bags')]), name='campaign_remove')
    assert again.wait(timeout=CAMPAIGN_TIMEOUT) == 0, again.output()[-4000:]
    moved = [row for row in read_csv(tmp_path / 'runs' / 'moved' / 'metrics_episodes.csv')
             if row['bag_path']]
    assert moved and all(verify_bag_files(row['bag_path']) is None for row in moved)
    assert not [path for worker in workers
                for path in (worker.bags_root / 'moved').glob('*')]


def files_of(directory: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(directory.iterdir())}
