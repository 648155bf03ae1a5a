"""The campaign's evaluator with its worker pairs: a result from a pair whose process died is
never a result.

The worker processes are real (stand-ins that sleep; one says 'simulator ready'), the action
clients are fakes whose results the test hands out, so the test decides exactly when a process
dies and what the dead pair answers. Marked ``graph``: the evaluator is built on a real rclpy
node (it needs the built workspace), though nothing travels over DDS.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest

from sessgan_evolver.campaign import CampaignConfig, EpisodeJob
from sessgan_evolver.process_supervisor import ProcessSupervisor, WorkerPool

pytestmark = pytest.mark.graph

SIMULATOR = [sys.executable, '-c',
             "import time; print('simulator ready', flush=True); time.sleep(120)"]
CONTROLLER = [sys.executable, '-c', 'import time; time.sleep(120)']


class Future:
    def __init__(self, value=None, done=False) -> None:
        self.value, self._done = value, done

    def done(self) -> bool:
        return self._done

    def result(self):
        return self.value

    def finish(self, value) -> None:
        self.value, self._done = value, True


class FakeClient:
    """An action client whose goals are accepted at once and finished by the test."""

    def __init__(self, goals: list) -> None:
        self.goals = goals

    def server_is_ready(self) -> bool:
        return True

    def send_goal_async(self, job):
        result = Future()
        handle = SimpleNamespace(accepted=True, get_result_async=lambda: result,
                                 cancel_goal_async=lambda: None)
        self.goals.append((job, result))
        return Future(handle, done=True)

    def destroy(self) -> None:
        pass


def finished(outcome: str):
    from action_msgs.msg import GoalStatus

    from sessgan_interfaces.msg import EpisodeMetrics

    metrics = EpisodeMetrics(outcome=outcome, collisions=1 if outcome != 'timeout' else 0)
    return SimpleNamespace(status=GoalStatus.STATUS_SUCCEEDED,
                           result=SimpleNamespace(metrics=metrics))


@pytest.fixture
def evaluator(ros_node, tmp_path):
    from sessgan_evolver.ros_evaluator import RosEvaluator

    with ProcessSupervisor(tmp_path / 'logs') as supervisor:
        pool = WorkerPool(supervisor)
        pool.start_pair('/w0', ('simulator_w0', SIMULATOR), ('controller_w0', CONTROLLER))
        logs: list[str] = []
        # A long episode timeout: a death must be seen without waiting for it.
        config = CampaignConfig(episode_timeout=600.0)
        evaluator = RosEvaluator(ros_node, config, tmp_path / 'bags', 'controller', supervisor,
                                 logs.append, pool)
        evaluator.goals = []
        evaluator.logs = logs
        evaluator.allowed = {'/w0/evaluate'}
        evaluator.evaluate_servers = lambda: ['/w0/evaluate']
        evaluator.action_client_class = lambda node, kind, name: FakeClient(evaluator.goals)
        evaluator.goal_for = lambda job: job
        yield evaluator


def run_with(evaluator, script) -> list:
    """Evaluate one job; ``script(goal_number, result_future)`` acts on each goal sent."""
    environment = SimpleNamespace(id='factory-g000-m00-s1', occupancy=np.zeros((32, 32)))
    job = EpisodeJob(0, 0, 0, environment, 1)
    results = []
    handled = set()
    deadline = time.monotonic() + 60.0

    def spin(seconds: float = 0.02) -> None:
        assert time.monotonic() < deadline, f'no result; log: {evaluator.logs}'
        time.sleep(seconds)
        for number, (_, result) in enumerate(evaluator.goals):
            if number not in handled:
                handled.add(number)
                script(number, result)

    evaluator.spin = spin
    evaluator.discover_workers()
    evaluator.evaluate([job], lambda job, metrics: results.append(metrics['outcome']))
    return results


def test_a_stopped_campaign_cancels_the_episodes_on_its_workers(evaluator):
    """Ctrl-C: the episodes running on the workers are cancelled, so a user's simulators do not
    run them on and write their bags into the stopped run."""
    cancelled = []
    client = FakeClient(evaluator.goals)
    send = client.send_goal_async

    def send_goal_async(job):
        future = send(job)
        future.value.cancel_goal_async = lambda: cancelled.append(job)
        return future

    client.send_goal_async = send_goal_async
    evaluator.action_client_class = lambda node, kind, name: client
    spins = []

    def spin(seconds: float = 0.02) -> None:
        spins.append(seconds)
        if len(spins) == 3:  # the goal is accepted by now: the user presses Ctrl-C
            raise KeyboardInterrupt

    evaluator.spin = spin
    evaluator.discover_workers()
    environment = SimpleNamespace(id='factory-g000-m00-s1', occupancy=np.zeros((32, 32)))
    job = EpisodeJob(0, 0, 0, environment, 1)
    with pytest.raises(KeyboardInterrupt):
        evaluator.evaluate([job], lambda job, metrics: None)
    assert cancelled == [job]


def test_controller_unresponsive_from_a_dead_controller_is_rerun_not_recorded(evaluator):
    pair = evaluator.pool.pairs['/w0']
    first_controller = pair.controller.process

    def script(number, result):
        if number == 0:  # the controller dies; its simulator reports it as unresponsive
            os.kill(first_controller.pid, signal.SIGKILL)
            first_controller.wait()
            result.finish(finished('controller_unresponsive'))
        else:
            result.finish(finished('collision_limit'))

    assert run_with(evaluator, script) == ['collision_limit']
    assert len(evaluator.goals) == 2 and pair.restarts == 1
    assert pair.controller.process.pid != first_controller.pid and pair.alive
    assert any('controller_w0' in line and 'killed by SIGKILL' in line
               and 'a harness failure, not a result' in line for line in evaluator.logs)


def test_a_dead_simulator_is_seen_at_once_and_its_episode_rerun(evaluator):
    pair = evaluator.pool.pairs['/w0']
    first_simulator = pair.simulator.process

    def script(number, result):
        if number == 0:  # the simulator dies mid-episode: no result will ever come
            os.kill(first_simulator.pid, signal.SIGKILL)
        else:
            result.finish(finished('timeout'))

    # run_with fails after 60 s, long before the 600 s episode timeout could act.
    assert run_with(evaluator, script) == ['timeout']
    assert pair.restarts == 1 and pair.simulator.process.pid != first_simulator.pid
    assert not any('gave no result' in line for line in evaluator.logs)


def test_a_restarted_pair_that_never_gets_ready_is_quarantined(evaluator, monkeypatch):
    from sessgan_evolver import ros_evaluator
    from sessgan_evolver.campaign import CampaignError

    monkeypatch.setattr(ros_evaluator, 'RESTART_READY_TIMEOUT', 1.0)
    pool = evaluator.pool
    pool.max_restarts = 1
    pair = pool.pairs['/w0']
    # From now on the simulator never says it is ready.
    pair.simulator.command = [sys.executable, '-c', 'import time; time.sleep(120)']

    def script(number, result):
        os.kill(pair.controller.process.pid, signal.SIGKILL)

    with pytest.raises(CampaignError, match='every simulator worker died repeatedly'):
        run_with(evaluator, script)
    assert any("did not log 'simulator ready' within 1 s" in line for line in evaluator.logs)
    assert pool.pairs == {} and '/w0' in pool.quarantined


@pytest.mark.parametrize('outcome', ['controller_unresponsive', 'cancelled', 'harness_error'])
def test_a_harness_outcome_of_a_live_pair_is_rerun_not_recorded(evaluator, outcome):
    """Under load a controller that is alive may still miss its 2 s: no result, run again."""
    pair = evaluator.pool.pairs['/w0']

    def script(number, result):
        result.finish(finished(outcome if number == 0 else 'goal_reached'))

    assert run_with(evaluator, script) == ['goal_reached']
    assert len(evaluator.goals) == 2 and pair.restarts == 0
    assert evaluator.harness_reruns == 1
    assert any(f'{outcome}' in line and 'a harness failure, not a result; running it again'
               in line for line in evaluator.logs)


def test_a_controller_silent_on_every_try_stops_the_run(evaluator):
    from sessgan_evolver.errors import HarnessFailureError

    def script(number, result):
        result.finish(finished('controller_unresponsive'))

    with pytest.raises(HarnessFailureError, match='silent on every one of 3 tries'):
        run_with(evaluator, script)
    assert len(evaluator.goals) == 3


def test_a_lost_bag_reported_by_the_worker_reaches_the_metrics(evaluator):
    def script(number, result):
        done = finished('timeout')
        done.result.metrics.bag_error = 'cannot write the failure bag: [Errno 28] No space left'
        result.finish(done)

    environment = SimpleNamespace(id='factory-g000-m00-s1', occupancy=np.zeros((32, 32)))
    handled: set[int] = set()

    def spin(seconds: float = 0.02) -> None:
        time.sleep(seconds)
        for number, (_, result) in enumerate(evaluator.goals):
            if number not in handled:
                handled.add(number)
                script(number, result)

    evaluator.spin = spin
    evaluator.discover_workers()
    results = []
    evaluator.evaluate([EpisodeJob(0, 0, 0, environment, 1)],
                       lambda job, metrics: results.append(metrics))
    assert [metrics['bag_error'] for metrics in results] == [
        'cannot write the failure bag: [Errno 28] No space left']


def test_an_episode_whose_worker_left_the_graph_is_taken_back_and_rerun(evaluator):
    """A worker whose action server vanishes mid-episode (its host gone: no result will come)
    has the episode taken back once it has been missing for GONE_GRACE, long before the
    episode timeout (600 s here); once back, it runs the episode again: one result."""
    import threading

    from sessgan_evolver.ros_evaluator import GONE_GRACE

    present = threading.Event()
    present.set()

    class VanishingClient(FakeClient):
        def server_is_ready(self) -> bool:
            return present.is_set()

    evaluator.action_client_class = lambda node, kind, name: VanishingClient(evaluator.goals)
    started = time.monotonic()

    def script(number, result):
        if number == 0:  # the host drops off; it comes back a while after the take-back
            present.clear()
            threading.Timer(GONE_GRACE + 1.0, present.set).start()
        else:
            result.finish(finished('timeout'))

    assert run_with(evaluator, script) == ['timeout']
    assert len(evaluator.goals) == 2
    assert GONE_GRACE <= time.monotonic() - started < 30.0
    assert any('left the ROS graph during the episode' in line and
               'a harness failure, not a result' in line for line in evaluator.logs), \
        evaluator.logs
    assert evaluator.harness_reruns == 1


def test_a_worker_gone_for_good_stops_the_run_as_a_harness_failure(evaluator, monkeypatch):
    """A worker that leaves mid-episode and never comes back, with no other one: the wait for a
    worker is said in the log, then the run stops as a harness failure (the campaign prints its
    --resume line), with what to do."""
    from sessgan_evolver import ros_evaluator
    from sessgan_evolver.errors import HarnessFailureError

    monkeypatch.setattr(ros_evaluator, 'NO_WORKER_TIMEOUT', 4.0)
    present = [True]

    class VanishingClient(FakeClient):
        def server_is_ready(self) -> bool:
            return present[0]

    evaluator.action_client_class = lambda node, kind, name: VanishingClient(evaluator.goals)

    def script(number, result):
        present[0] = False  # the host drops off during the first episode, for good

    with pytest.raises(HarnessFailureError, match=r'no simulator worker has been available '
                       r'for 4 s \(1 episodes left to run\); the logs of the workers'):
        run_with(evaluator, script)
    assert any('no simulator worker answers: waiting up to 4 s' in line
               for line in evaluator.logs), evaluator.logs


def test_an_unanswered_goal_is_sent_again_through_a_new_client(evaluator, monkeypatch):
    """A goal the worker never answers (lost on its way) goes again through a new client: its
    DDS endpoints are matched afresh, where the old ones may never deliver."""
    from sessgan_evolver import ros_evaluator

    monkeypatch.setattr(ros_evaluator, 'GOAL_ANSWER_TIMEOUT', 0.3)
    made: list[FakeClient] = []

    class DeafClient(FakeClient):
        def send_goal_async(self, job):
            self.goals.append((job, Future()))
            return Future()  # never answered

    def client_for(node, kind, name):
        made.append((DeafClient if not made else FakeClient)(evaluator.goals))
        return made[-1]

    evaluator.action_client_class = client_for

    def script(number, result):
        result.finish(finished('timeout'))

    assert run_with(evaluator, script) == ['timeout']
    assert len(made) == 2 and len(evaluator.goals) == 2
    assert any('did not answer the goal' in line for line in evaluator.logs), evaluator.logs


def test_an_action_with_only_a_client_is_no_worker(ros_node):
    """A client of an evaluate action puts the action's name in the graph; only a server
    makes it a worker (a client left over in another process is none)."""
    from rclpy.action import ActionClient, ActionServer, get_action_names_and_types

    from sessgan_evolver.ros_evaluator import EVALUATE_TYPE, served_actions
    from sessgan_interfaces.action import EvaluateEnvironment
    from tests.ros_processes import spin_until

    ActionClient(ros_node, EvaluateEnvironment, '/lone_client/evaluate')
    ActionServer(ros_node, EvaluateEnvironment, '/served/evaluate', lambda handle: None)
    assert spin_until(ros_node, lambda: {'/lone_client/evaluate', '/served/evaluate'} <= {
        name for name, _ in get_action_names_and_types(ros_node)}, timeout=20)
    assert spin_until(ros_node, lambda: '/served/evaluate' in served_actions(
        ros_node, EVALUATE_TYPE), timeout=20)
    assert '/lone_client/evaluate' not in served_actions(ros_node, EVALUATE_TYPE)


class Describing:
    """A worker's bags service as identity_checked sees it: up or not, and what it says."""

    def __init__(self, up: bool, version: str = '', robot: str = '') -> None:
        import json

        self.service = '/w0/bags'
        self.client = SimpleNamespace(service_is_ready=lambda: up)
        self.description = SimpleNamespace(software_version=version,
                                           settings=json.dumps({'robot': robot}))

    def call_within(self, timeout: float):
        return self.description


@pytest.mark.parametrize('source, refusal', [
    (Describing(True, '0.1.0', ''), None),
    (Describing(True, '0.0.9', ''), 'runs sessgan 0.0.9, this campaign 0.1.0'),
    (Describing(True, '0.1.0', 'flyer'), "hosts robot 'flyer'"),
    (Describing(False), 'serves no /w0/bags service within'),
])
def test_a_worker_is_used_only_if_it_says_it_matches(evaluator, monkeypatch, source, refusal):
    import sessgan_evolver.ros_evaluator as ros_evaluator

    monkeypatch.setattr(ros_evaluator, 'IDENTITY_TIMEOUT', 0.2)
    evaluator.expected_robot = 'diff_drive'
    evaluator.bag_sources['/w0'] = source
    found = evaluator.discover_workers()
    if refusal is None:
        assert found == ['/w0/evaluate']
        return
    if not source.client.service_is_ready():  # not up yet: looked at again, not waited for
        assert found == [] and not evaluator.refused
        time.sleep(0.3)
        found = evaluator.discover_workers()
    assert found == [] and evaluator.refused == {'/w0/evaluate'}
    assert any(line.startswith('refusing worker /w0/evaluate') and refusal in line
               for line in evaluator.logs), evaluator.logs


def test_a_worker_two_simulators_serve_is_not_used_until_one_stops(evaluator, ros_node):
    """Two simulators started under one namespace both take each goal, and their answers
    cross ("harness failure ... ended the goal with status 0"): say so, use it once one is
    left."""
    from rclpy.action import ActionServer

    from sessgan_interfaces.action import EvaluateEnvironment
    from tests.ros_processes import spin_until

    servers = [ActionServer(ros_node, EvaluateEnvironment, '/dup/evaluate', lambda h: None)
               for _ in range(2)]
    status = '/dup/evaluate/_action/status'
    assert spin_until(ros_node, lambda: ros_node.count_publishers(status) == 2, timeout=20)
    evaluator.allowed = None
    evaluator.evaluate_servers = lambda: ['/dup/evaluate']
    assert evaluator.discover_workers() == [] and evaluator.discover_workers() == []
    said = [line for line in evaluator.logs if 'not using worker /dup/evaluate' in line]
    assert len(said) == 1 and 'while 2 simulators serve it' in said[0], evaluator.logs
    servers[1].destroy()
    assert spin_until(ros_node, lambda: ros_node.count_publishers(status) == 1, timeout=20)
    assert evaluator.discover_workers() == ['/dup/evaluate']
