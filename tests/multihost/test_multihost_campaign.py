"""A campaign on one host, its workers on two others: hosts made of network namespaces joined
by a bridge (network_namespaces.py), DDS discovery across them by SUBNET multicast
(conftest.dds_environment). Runs as root only; skipped elsewhere with the reason."""

from __future__ import annotations

import csv
import os
import re
import signal
import sys
import time
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
        '--method', 'sessgan', '--scenario', 'factory', '--generations', '1', '--population', '2',
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
        '--method', 'sessgan', '--scenario', 'factory', '--generations', '1', '--population', '2',
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


@pytest.mark.parametrize('fault', ['processes_killed', 'interface_deleted', 'link_down'])
def test_a_worker_host_lost_mid_episode_is_replaced_and_used_again_when_back(
        multihost, tmp_path, fault):
    """Worker /w1 is lost in the middle of an episode: its processes killed (SIGKILL, no
    goodbye to DDS), its host's interface deleted, or its link taken down (the processes
    still run in both). The campaign takes the episode back once /w1 leaves the graph, runs
    it on /w0, never records it, and gives /w1 work again once it is back: restarted; its
    interface made again and its processes restarted (measured: Fast DDS processes that
    outlived the deletion of their interface were not discovered again within 30 s after it
    was re-made); its link up again, the same processes."""
    network, processes = multihost
    # Clocked at real time: an episode lasts up to its 6 sim s in wall time, so 'mid-episode'
    # is a wide window.
    clocked = ('-p', 'mode:=clocked', '-p', 'real_time_factor:=1.0')
    start_worker(network, processes, 'worker_a', '/w0', tmp_path / 'bags_a', *clocked)
    start_worker(network, processes, 'worker_b', '/w1', tmp_path / 'bags_b', *clocked)
    for process in processes.processes[::2]:
        process.wait_for_output('simulator ready', timeout=120.0)
    w1_simulator, w1_controller = processes.processes[2:4]
    # 6 episodes a generation for 2 workers: /w1 is given the next one as soon as it ends one.
    campaign = processes.start(campaign_command(network, [
        '--method', 'sessgan', '--scenario', 'factory', '--generations', '2', '--population', '2',
        '--maps-per-member', '3', '--time-limit', '6', '--seed', '5', '--run', 'faulty',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')]),
        name='campaign')
    w1_simulator.wait_for_output(EPISODE_LOG.pattern, timeout=180.0)
    time.sleep(2.0)  # 2 s into its next episode
    if fault == 'processes_killed':
        kill(w1_simulator, w1_controller)
    elif fault == 'interface_deleted':
        network.unplug('worker_b')
    else:
        network.link('worker_b', up=False)
    campaign.wait_for_output(r'/w1/evaluate \(left the ROS graph during the episode.*'
                             r'a harness failure, not a result', timeout=120.0)
    if fault == 'link_down':
        network.link('worker_b', up=True)
    else:
        if fault == 'interface_deleted':
            kill(w1_simulator, w1_controller)
            network.plug('worker_b')
        start_worker(network, processes, 'worker_b', '/w1', tmp_path / 'bags_b', *clocked)
        w1_simulator = processes.processes[-2]
        w1_simulator.wait_for_output('simulator ready', timeout=120.0)
    episodes_before = len(EPISODE_LOG.findall(w1_simulator.output()))
    assert campaign.wait(timeout=CAMPAIGN_TIMEOUT) == 0, campaign.output()[-4000:]
    rows = read_csv(tmp_path / 'runs' / 'faulty' / 'metrics_episodes.csv')
    assert len(rows) == 12  # every episode once: the one cut off has no row of its own
    assert all(row['outcome'] != 'cancelled' for row in rows)
    with open(tmp_path / 'runs' / 'faulty' / 'metrics_generations.csv') as handle:
        assert sum(int(row['harness_reruns']) for row in csv.DictReader(handle)) >= 1
    # Used again once back: it ran episodes and the campaign collected their bags from it.
    assert len(EPISODE_LOG.findall(w1_simulator.output())) > episodes_before, \
        'the worker that came back was never used again'
    back = campaign.output().split('left the ROS graph', 1)[1]
    assert 'collected from /w1' in back, back[-3000:]


# A simulator that says it is another version, as one installed from another release would.
OTHER_VERSION_SIMULATOR = [sys.executable, '-c', (
    'import sys, sessgan_sim; sessgan_sim.__version__ = "0.0.9"; '
    'from sessgan_sim.simulator_node import main; sys.exit(main(sys.argv))')]


def test_workers_of_another_domain_version_or_scenario_are_not_used(multihost, tmp_path):
    """Beside a good worker /w0: /w1 in another ROS_DOMAIN_ID (never seen), /w2 of another
    software version and /w3 set up for the race track's car (both refused, the difference
    named). Every episode runs on /w0."""
    network, processes = multihost
    other_domain = {'ROS_DOMAIN_ID': str(int(processes.env['ROS_DOMAIN_ID']) + 1)}
    start_worker(network, processes, 'worker_a', '/w0', tmp_path / 'bags_a')
    start_worker(network, processes, 'worker_a', '/w1', tmp_path / 'bags_a', env=other_domain)
    start_worker(network, processes, 'worker_b', '/w2', tmp_path / 'bags_b', controller=False,
                 simulator=OTHER_VERSION_SIMULATOR)
    start_worker(network, processes, 'worker_b', '/w3', tmp_path / 'bags_b', '-p',
                 'robot:=car', controller=False)
    for process in processes.processes:
        if process.name.startswith('simulator'):
            process.wait_for_output('simulator ready', timeout=120.0)
    campaign = processes.start(campaign_command(network, [
        '--method', 'sessgan', '--scenario', 'factory', '--generations', '1', '--population', '2',
        '--maps-per-member', '2', '--time-limit', '10', '--seed', '3', '--run', 'picky',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')]),
        name='campaign')
    assert campaign.wait(timeout=CAMPAIGN_TIMEOUT) == 0, campaign.output()[-4000:]
    log = campaign.output()
    assert 'worker found: /w0/evaluate' in log
    assert '/w1/' not in log, 'a worker of another ROS domain was seen'
    assert ('refusing worker /w2/evaluate runs sessgan 0.0.9, this campaign 0.1.0: install '
            'the same version on every host') in log
    assert ("refusing worker /w3/evaluate hosts robot 'car' (its simulator parameter robot), "
            "the campaign's scenario factory needs 'diff_drive'") in log
    assert 'worker found: /w2' not in log and 'worker found: /w3' not in log
    w0_episodes = len(EPISODE_LOG.findall(processes.processes[0].output()))
    assert w0_episodes == 4 == len(read_csv(tmp_path / 'runs' / 'picky' /
                                            'metrics_episodes.csv'))


def kill(*node_processes) -> None:
    for process in node_processes:
        os.killpg(process.process.pid, signal.SIGKILL)
        process.process.wait(timeout=10)
