"""Hosts made of Linux network namespaces on one machine, for the multi-host tests.

:class:`NamespaceNetwork` makes a switch namespace holding a bridge and one namespace per host,
each joined to the bridge by a veth pair whose two ends are created directly inside their
namespaces: the machine's own network namespace gets no interface, address or route, so DDS
traffic of the test can reach nothing outside it (and nothing outside reaches it). Names carry a
per-run tag; everything is removed on exit, also when the test fails, by deleting the
namespaces (which deletes the interfaces in them).

Needs root and iproute2 with ``ip netns``: :func:`unavailable_reason` says why not.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass

SUBNET_PREFIX = '10.231'
"""Private /24s under 10.231.<n>.0, n from the run's tag, only ever inside the namespaces."""


def unavailable_reason() -> str:
    """Why namespaces cannot be made here ('' when they can)."""
    if not hasattr(os, 'geteuid') or os.geteuid() != 0:
        return 'needs root to create network namespaces (run the test as root)'
    if shutil.which('ip') is None:
        return "needs iproute2's 'ip' command"
    probe = subprocess.run(['ip', 'netns', 'list'], capture_output=True, text=True)
    if probe.returncode != 0:
        return f"'ip netns' does not work here: {probe.stderr.strip()}"
    return ''


def ip(*arguments: str) -> None:
    """Run ``ip ...``; RuntimeError with its message if it fails."""
    done = subprocess.run(['ip', *arguments], capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f'ip {" ".join(arguments)}: {done.stderr.strip()}')


@dataclass(frozen=True)
class Host:
    name: str
    """Short name in the test ('campaign', 'worker_a', ...)."""
    namespace: str
    interface: str
    """Its end of the veth pair, inside ``namespace``."""
    address: str

    def command(self, argv: list[str]) -> list[str]:
        """``argv`` run inside this host's namespace."""
        return ['ip', 'netns', 'exec', self.namespace, *argv]


class NamespaceNetwork:
    """A bridge in a switch namespace and ``hosts`` namespaces on one /24 (module docstring).

    ``tag``: unique to the run (at most 6 characters, letters and digits), part of every name.
    """

    def __init__(self, tag: str, hosts: list[str], subnet: int) -> None:
        if not tag.isalnum() or len(tag) > 6:
            raise ValueError(f'tag must be at most 6 letters or digits, got {tag!r}')
        self.tag = tag
        self.subnet = f'{SUBNET_PREFIX}.{subnet}'
        self.switch = f'sgs{tag}'
        self.hosts = {name: Host(name, f'sgh{tag}{index}', f'h{index}', f'{self.subnet}.'
                                 f'{index + 10}') for index, name in enumerate(hosts)}
        self.made: list[str] = []

    def __enter__(self) -> NamespaceNetwork:
        try:
            self.create()
        except BaseException:
            self.remove()
            raise
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.remove()

    def create(self) -> None:
        self._namespace(self.switch)
        ip('-n', self.switch, 'link', 'add', 'br0', 'type', 'bridge')
        # No IGMP querier on this bridge: flood multicast (DDS discovery) to every port.
        ip('-n', self.switch, 'link', 'set', 'br0', 'type', 'bridge', 'mcast_snooping', '0')
        ip('-n', self.switch, 'link', 'set', 'br0', 'up')
        for host in self.hosts.values():
            self._namespace(host.namespace)
            self.plug(host.name)

    def plug(self, name: str) -> None:
        """Join host ``name`` to the bridge: a veth pair (its end ``host.interface``, the
        switch's end on the bridge), its address, and the route for DDS multicast discovery
        (the namespace has no default route)."""
        host = self.hosts[name]
        port = f'p{list(self.hosts).index(name)}'
        ip('link', 'add', 'name', host.interface, 'netns', host.namespace, 'type', 'veth',
           'peer', 'name', port, 'netns', self.switch)
        ip('-n', self.switch, 'link', 'set', port, 'master', 'br0')
        ip('-n', self.switch, 'link', 'set', port, 'up')
        ip('-n', host.namespace, 'link', 'set', 'lo', 'up')
        ip('-n', host.namespace, 'addr', 'add', f'{host.address}/24', 'dev', host.interface)
        ip('-n', host.namespace, 'link', 'set', host.interface, 'up')
        ip('-n', host.namespace, 'route', 'add', '224.0.0.0/4', 'dev', host.interface)

    def unplug(self, name: str) -> None:
        """Delete host ``name``'s interface (the veth pair goes with it), as a host that drops
        off the network: its processes keep running."""
        host = self.hosts[name]
        ip('-n', host.namespace, 'link', 'del', host.interface)

    def link(self, name: str, up: bool) -> None:
        """Take host ``name``'s link down (a pulled cable: interface, address and processes
        stay) or up again."""
        host = self.hosts[name]
        ip('-n', host.namespace, 'link', 'set', host.interface, 'up' if up else 'down')
        if up:  # the kernel dropped the route with the link
            ip('-n', host.namespace, 'route', 'replace', '224.0.0.0/4', 'dev', host.interface)

    def _namespace(self, name: str) -> None:
        ip('netns', 'add', name)
        self.made.append(name)

    def remove(self) -> None:
        """Delete every namespace made (their interfaces go with them); errors are collected
        and raised once all were tried."""
        errors = []
        for name in reversed(self.made):
            try:
                ip('netns', 'del', name)
            except RuntimeError as err:
                errors.append(str(err))
        self.made.clear()
        if errors:
            raise RuntimeError('; '.join(errors))


def leftover_namespaces(tag: str) -> list[str]:
    """Namespaces of the run ``tag`` that still exist."""
    listed = subprocess.run(['ip', 'netns', 'list'], capture_output=True, text=True).stdout
    return [line.split()[0] for line in listed.splitlines()
            if line.split() and line.split()[0].startswith(('sgs' + tag, 'sgh' + tag))]
