"""The simulator's NavigateToPose client never drops the answer to a request it just sent.

rclpy 7.1 files a request's future only after sending it; an answer that the executor thread
handles in between is dropped and the future never completes (ros2/rclpy#1123). Seen in a
fresh-clone test run on a loaded machine: the Nav2 stand-in accepted the goal, the simulator
logged "Ignoring unexpected goal response" and the episode ended controller_unresponsive.
Here the window is widened on purpose: sending a request returns only after the server's
answer has had time to arrive and be handled.
"""

from __future__ import annotations

import threading
import time

import pytest

SEND_DELAY = 0.5
"""Wall seconds between sending a request and returning from the send (the race's window)."""


class SlowSending:
    """rclpy's client handle, returning from each send only ``SEND_DELAY`` s after it."""

    def __init__(self, handle) -> None:
        self._handle = handle

    def __getattr__(self, name):
        return getattr(self._handle, name)

    def __enter__(self):
        return self._handle.__enter__()

    def __exit__(self, *exc):
        return self._handle.__exit__(*exc)

    def _slowly(self, send, request):
        sequence_number = send(request)
        time.sleep(SEND_DELAY)
        return sequence_number

    def send_goal_request(self, request):
        return self._slowly(self._handle.send_goal_request, request)

    def send_result_request(self, request):
        return self._slowly(self._handle.send_result_request, request)


@pytest.fixture
def served_node(ros_node):
    """(node, executor): a node with a NavigateToPose server that accepts and succeeds every
    goal, spun by a multi-threaded executor in the background, as the simulator's is."""
    from nav2_msgs.action import NavigateToPose
    from rclpy.action import ActionServer
    from rclpy.executors import MultiThreadedExecutor

    def succeed(goal_handle):
        goal_handle.succeed()
        return NavigateToPose.Result()

    server = ActionServer(ros_node, NavigateToPose, 'navigate_to_pose', succeed)
    executor = MultiThreadedExecutor(num_threads=2, context=ros_node.context)
    executor.add_node(ros_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        yield ros_node
    finally:
        executor.shutdown()
        spinner.join(timeout=5.0)
        server.destroy()


def goal_and_result(client, timeout: float = 5.0) -> tuple[bool, bool]:
    """(goal answered, result answered) of one NavigateToPose goal sent by ``client``."""
    from nav2_msgs.action import NavigateToPose

    assert client.wait_for_server(timeout_sec=10.0), 'the action server was not found'
    client._client_handle = SlowSending(client._client_handle)
    sent = client.send_goal_async(NavigateToPose.Goal())
    deadline = time.monotonic() + timeout
    while not sent.done() and time.monotonic() < deadline:
        time.sleep(0.01)
    if not sent.done():
        return False, False
    result = sent.result().get_result_async()
    while not result.done() and time.monotonic() < deadline + timeout:
        time.sleep(0.01)
    return True, result.done()


def test_an_answer_that_comes_while_the_goal_is_sent_is_not_lost(served_node):
    from nav2_msgs.action import NavigateToPose

    from sessgan_sim.worker.nav2_stack import FilingActionClient

    client = FilingActionClient(served_node, NavigateToPose, 'navigate_to_pose')
    assert goal_and_result(client) == (True, True)


def test_rclpy_s_own_client_loses_it(served_node):
    """The race the filing client works around, shown on rclpy's own client: when this fails,
    the pinned rclpy has the upstream fix and FilingActionClient can go."""
    from nav2_msgs.action import NavigateToPose
    from rclpy.action import ActionClient

    client = ActionClient(served_node, NavigateToPose, 'navigate_to_pose')
    assert goal_and_result(client, timeout=2.0) == (False, False)
