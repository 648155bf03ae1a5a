"""Starting and stopping a campaign's child processes: pinning, batch scheduling, clean stop."""

from __future__ import annotations

import os
import signal
import sys
import time

import pytest

from sessgan_evolver.process_supervisor import ProcessSupervisor, WorkerPool, worker_cores

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


def announcing_sleeper(text: str, delay: float = 0.0) -> list[str]:
    """A process that prints ``text`` after ``delay`` seconds and then sleeps (a simulator
    saying it is ready)."""
    return [sys.executable, '-c',
            f'import time; time.sleep({delay}); print({text!r}, flush=True); time.sleep(60)']


def wait_until(predicate, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, 'timed out'
        time.sleep(0.02)


def test_a_dead_controller_is_seen_at_once_and_its_pair_restarted(tmp_path):
    with ProcessSupervisor(tmp_path) as supervisor:
        pool = WorkerPool(supervisor, max_restarts=2)
        # The announcement comes 1 s after start, so a restarted simulator has not yet made it
        # when the assertion below runs: only the predecessor's log line could satisfy it.
        pair = pool.start_pair('/w0', ('simulator_w0', announcing_sleeper('simulator ready', 1.0)),
                               ('controller_w0', SLEEPER))
        other = pool.start_pair('/w1', ('simulator_w1', SLEEPER), ('controller_w1', SLEEPER))
        wait_until(lambda: pair.logged_since_start('simulator ready'))
        assert pool.dead_pairs() == []
        old_simulator, old_controller = pair.simulator, pair.controller
        os.kill(old_controller.process.pid, signal.SIGKILL)
        wait_until(lambda: pool.dead_pairs() == [pair], timeout=2.0)
        assert pair.death_report() == \
            f'controller_w0 (pid {old_controller.process.pid}) was killed by SIGKILL'
        assert pool.restart(pair)
        # Both processes are new; the survivor was stopped, the other pair left alone.
        assert old_simulator.process.poll() is not None
        assert pair.simulator.process.pid != old_simulator.process.pid
        assert pair.alive and pair.restarts == 1 and other.alive and other.restarts == 0
        # Readiness is judged by the new process's own output, not its predecessor's log.
        assert not pair.logged_since_start('simulator ready')
        wait_until(lambda: pair.logged_since_start('simulator ready'))
        assert pair.simulator.log_path.read_text().count('simulator ready') == 2
        assert sorted(child.name for child in supervisor.children) == [
            'controller_w0', 'controller_w1', 'simulator_w0', 'simulator_w1']


def test_a_pair_that_keeps_dying_is_quarantined(tmp_path):
    crashing = [sys.executable, '-c', 'raise SystemExit(3)']
    with ProcessSupervisor(tmp_path) as supervisor:
        pool = WorkerPool(supervisor, max_restarts=2)
        pair = pool.start_pair('/w0', ('simulator_w0', crashing), ('controller_w0', SLEEPER))
        for restart in (1, 2):
            wait_until(lambda: pool.dead_pairs() == [pair])
            assert 'simulator_w0' in pair.death_report()
            assert 'exited with status 3' in pair.death_report()
            assert pool.restart(pair) and pair.restarts == restart
        wait_until(lambda: pool.dead_pairs() == [pair])
        controller = pair.controller
        assert not pool.restart(pair)
        assert pool.pairs == {} and pool.quarantined == {'/w0': pair}
        assert controller.process.poll() is not None and supervisor.children == []


def test_a_child_is_stopped_by_sigint_even_where_its_parent_ignores_it(tmp_path):
    """A campaign started in the background by a non-interactive shell (`cmd &`) has SIGINT
    ignored; its children are stopped by SIGINT at once all the same, not by SIGKILL after
    the grace (a plain Python child would otherwise never install its handler)."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with ProcessSupervisor(tmp_path) as supervisor:
            child = supervisor.start('sleeper', [
                sys.executable, '-c', "import time; print('asleep', flush=True); time.sleep(60)"])
            # Past the interpreter's start-up (a SIGINT there can end it with 1, under load).
            deadline = time.monotonic() + 60
            while 'asleep' not in child.output():
                assert time.monotonic() < deadline, child.output()
                time.sleep(0.05)
            started = time.monotonic()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert child.process.returncode == -signal.SIGINT  # not -SIGKILL
    assert time.monotonic() - started < 4.0  # well within the 5 s grace

