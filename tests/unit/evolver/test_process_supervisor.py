"""Starting and stopping a campaign's child processes: pinning, batch scheduling, clean stop."""

from __future__ import annotations

import os
import sys

import pytest

from sessgan_evolver.process_supervisor import ProcessSupervisor, worker_cores

pytestmark = pytest.mark.unit

SLEEPER = [sys.executable, '-c', 'import time; time.sleep(60)']


def test_worker_pairs_go_round_robin_over_the_allowed_cores():
    allowed = sorted(os.sched_getaffinity(0))
    cores = worker_cores(2 * len(allowed) + 1)
    assert cores == [allowed[i % len(allowed)] for i in range(2 * len(allowed) + 1)]


def test_a_child_is_pinned_and_batch_scheduled_and_stopped(tmp_path):
    core = sorted(os.sched_getaffinity(0))[-1]
    with ProcessSupervisor(tmp_path) as supervisor:
        pinned = supervisor.start('pinned', SLEEPER, core=core, batch=True)
        plain = supervisor.start('plain', SLEEPER)
        assert os.sched_getaffinity(pinned.process.pid) == {core}
        assert os.sched_getscheduler(pinned.process.pid) == os.SCHED_BATCH
        assert os.sched_getscheduler(plain.process.pid) == os.SCHED_OTHER
        assert os.sched_getaffinity(plain.process.pid) == os.sched_getaffinity(0)
    assert pinned.process.poll() is not None and plain.process.poll() is not None
