"""A campaign on one host, its workers on two others: hosts made of network namespaces joined
by a bridge (network_namespaces.py), DDS discovery across them by SUBNET multicast
(conftest.dds_environment). Runs as root only; skipped elsewhere with the reason."""

from __future__ import annotations

import csv
import re

import pytest

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
