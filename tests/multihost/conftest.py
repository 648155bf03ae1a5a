"""Fixtures of the multi-host tests: hosts made of network namespaces (network_namespaces.py)
and the environment that lets DDS cross them."""

from __future__ import annotations

import random
import secrets
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.multihost.network_namespaces import (
    NamespaceNetwork,
    leftover_namespaces,
    unavailable_reason,
)

EXTERNAL_CONTROLLER = Path(__file__).resolve().parents[1] / 'graph' / 'external_controller.py'


def dds_environment(domain: int) -> dict[str, str]:
    """What every process of a multi-host test runs with.

    SUBNET: discovery by multicast on the namespaces' one link (measured on this machine:
    a probe in another namespace saw a worker's action in 0.2 s; with LOCALHOST it saw nothing
    in 30 s, and with LOCALHOST plus ROS_STATIC_PEERS of every address it took 3.2 s).
    UDPv4 only: Fast DDS otherwise moves data through shared memory between participants it
    takes for one host, and the namespaces share /dev/shm, so a cut link would not cut them.
    """
    return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', 'ROS_DOMAIN_ID': str(domain),
            'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4', 'ROS_STATIC_PEERS': ''}


@dataclass
class Worker:
    host: str
    namespace: str
    """ROS namespace of its simulator + controller: '/w0', ..."""
    bags_root: Path


@pytest.fixture
def network(request):
    """Hosts 'campaign', 'worker_a', 'worker_b' (another list by indirect parametrization);
    removed at teardown, and checked gone."""
    reason = unavailable_reason()
    if reason:
        pytest.skip(f'multi-host test: {reason}')
    tag = secrets.token_hex(3)
    hosts = getattr(request, 'param', ['campaign', 'worker_a', 'worker_b'])
    with NamespaceNetwork(tag, hosts, subnet=random.SystemRandom().randrange(1, 250)) as net:
        yield net
    assert not leftover_namespaces(tag), 'namespaces of this run were left behind'


@pytest.fixture
def multihost(network, node_processes):
    """``(network, node_processes)`` in a ROS domain of their own: the processes are stopped
    before the namespaces are removed (fixtures tear down in reverse order)."""
    domain = random.SystemRandom().randrange(100, 200)
    node_processes.env.update(dds_environment(domain))
    return network, node_processes


def start_worker(network: NamespaceNetwork, processes, host: str, namespace: str,
                 bags_root: Path, *simulator_parameters: str, controller: bool = True,
                 env: dict[str, str] | None = None,
                 simulator: list[str] | None = None) -> Worker:
    """A simulator (``simulator``: its command, default ``ros2 run sessgan_sim simulator``)
    and, with ``controller``, the external example controller (``--blind``: it drives
    straight on, so valid maps end in failures) under ``namespace`` in ``host``'s
    namespace."""
    where = network.hosts[host]
    processes.start(where.command(
        [*(simulator or ['ros2', 'run', 'sessgan_sim', 'simulator']), '--ros-args', '-r',
         f'__ns:={namespace}', '-p', f'bags_root:={bags_root}', *simulator_parameters]),
        name=f'simulator{namespace.replace("/", "_")}', env=env)
    if controller:
        processes.start(where.command(
            [sys.executable, str(EXTERNAL_CONTROLLER), '--blind', '--ros-args', '-r',
             f'__ns:={namespace}', '-p', 'use_sim_time:=true']),
            name=f'controller{namespace.replace("/", "_")}', env=env)
    return Worker(host, namespace, bags_root)


def campaign_command(network: NamespaceNetwork, arguments: list[str]) -> list[str]:
    return network.hosts['campaign'].command(
        ['ros2', 'run', 'sessgan_evolver', 'campaign', '--external', *arguments])
