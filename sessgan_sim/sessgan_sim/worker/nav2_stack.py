"""Driving a Nav2 stack the way its users do: NavigateToPose goals and costmap resets.

Names are relative, so they follow the worker's namespace: the ``navigate_to_pose`` action
server (bt_navigator) and the ClearEntireCostmap services of Nav2's two costmaps,
``global_costmap/clear_entirely_global_costmap`` and
``local_costmap/clear_entirely_local_costmap``. Every call waits at most ``timeout`` wall
seconds and reports a failure as a sentence for the episode's detail (the episode then ends
as controller_unresponsive: the stack under test did not respond). The futures are completed
by the node's executor in another thread while an episode runs in the evaluate callback.

A goal sent on ``goal_pose`` alone has no answer, but Nav2's bt_navigator makes each one a
NavigateToPose goal of its own server, so the server's status topic
(``navigate_to_pose/_action/status``) says when the stack gave up on it (aborted: no path, a
failed recovery) or reached it. A stack that gave up stands still and sends nothing, which
must read as a navigation failure, not as a silent (dead) stack.

nav2_msgs is imported when first needed: a worker that never drives Nav2 runs without it.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.action import ActionClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from sessgan_sim import ros_messages as rm
from sessgan_sim.worker.topics import time_of

NAVIGATE_ACTION = 'navigate_to_pose'
RESET_SERVICES = ('global_costmap/clear_entirely_global_costmap',
                  'local_costmap/clear_entirely_local_costmap')
POLL = 0.005
"""Seconds between checks of a pending future."""

TERMINAL = {GoalStatus.STATUS_SUCCEEDED: 'succeeded', GoalStatus.STATUS_ABORTED: 'aborted',
            GoalStatus.STATUS_CANCELED: 'canceled'}
STATUS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""An action server's status topic (rcl_action's default status QoS; a deeper reader queue,
so a goal's short-lived states are not overwritten before they are read)."""


class Nav2Stack:
    """The action client and service clients of one worker, created on first use."""

    def __init__(self, node, callback_group, running) -> None:
        """``running()``: False once the worker stops (every wait ends then)."""
        self.node = node
        self.callback_group = callback_group
        self.running = running
        self._action_client: Any = None
        self._reset_clients: dict[str, Any] = {}
        self._goal_handle: Any = None
        self._result_future: Any = None
        self._status_subscription: Any = None
        self._statuses: GoalStatusArray | None = None
        """The latest status of the stack's navigate_to_pose server (None: none seen)."""
        self._known_goals: set[bytes] | None = None
        """Ids of the server's goals when this episode's goal went out on goal_pose (None:
        no goal_pose goal is watched)."""
        self._seen_active: set[bytes] = set()
        """Goals not known then that were seen pursued since: only these can be ours (an old
        goal's end, delivered late by the transient-local topic, is not)."""
        self._watched_status: int | None = None
        """The status of the newest of those, updated as statuses arrive (read every tick)."""

    # ---- resets ----------------------------------------------------------------------------

    def reset_costmaps(self, timeout: float) -> str | None:
        """Clear both costmaps; None when both answered, else why not."""
        from nav2_msgs.srv import ClearEntireCostmap

        for name in RESET_SERVICES:
            client = self._reset_clients.get(name)
            if client is None:
                client = self.node.create_client(ClearEntireCostmap, name,
                                                 callback_group=self.callback_group)
                self._reset_clients[name] = client
            service = self.node.resolve_service_name(name)
            deadline = time.monotonic() + timeout
            if not self._wait_until(client.service_is_ready, deadline):
                return (f'costmap reset: no {service} service within {timeout:.1f} s wall time '
                        '(reset_costmaps is on: is Nav2 running under this namespace?)')
            future = client.call_async(ClearEntireCostmap.Request())
            if not self._wait_until(future.done, deadline):
                client.remove_pending_request(future)
                return f'costmap reset: {service} did not answer within {timeout:.1f} s wall time'
        return None

    # ---- the goal --------------------------------------------------------------------------

    def send_goal(self, goal, stamp_ns: int, timeout: float) -> str | None:
        """Send ``goal`` (map frame) as a NavigateToPose goal; None once the server accepted
        it, else why not."""
        from nav2_msgs.action import NavigateToPose

        if self._action_client is None:
            self._action_client = FilingActionClient(self.node, NavigateToPose, NAVIGATE_ACTION,
                                                     callback_group=self.callback_group)
        client = self._action_client
        name = self.node.resolve_topic_name(NAVIGATE_ACTION)
        self._goal_handle = self._result_future = None
        deadline = time.monotonic() + timeout
        if not self._wait_until(client.server_is_ready, deadline):
            return (f'no NavigateToPose action server at {name} within {timeout:.1f} s wall '
                    'time (goal_interface sends the goal there)')
        request = NavigateToPose.Goal(
            pose=rm.goal_msg(time_of(stamp_ns), goal.x, goal.y, goal.yaw))
        sent = client.send_goal_async(request)
        if not self._wait_until(sent.done, deadline):
            return f'{name} did not answer the goal within {timeout:.1f} s wall time'
        handle = sent.result()
        if handle is None or not handle.accepted:
            return f'{name} rejected the goal'
        self._goal_handle = handle
        self._result_future = handle.get_result_async()
        return None

    def watch_goal(self) -> None:
        """A goal goes out on goal_pose: from now on the stack's server's status says how the
        goal that bt_navigator makes of it ends."""
        if self._status_subscription is None:
            self._status_subscription = self.node.create_subscription(
                GoalStatusArray, f'{NAVIGATE_ACTION}/_action/status', self._on_status,
                STATUS_QOS, callback_group=self.callback_group)
        statuses = self._statuses
        self._seen_active = set()
        self._watched_status = None
        self._known_goals = set() if statuses is None else {
            bytes(status.goal_info.goal_id.uuid) for status in statuses.status_list}

    def _on_status(self, statuses: GoalStatusArray) -> None:
        """Keep the latest status; while a goal_pose goal is watched, the status of the newest
        goal the server took since (a goal_pose's; a newer one preempts it, as bt_navigator
        does)."""
        known = self._known_goals
        if known is not None:
            ids = [bytes(status.goal_info.goal_id.uuid) for status in statuses.status_list]
            self._seen_active |= {goal for goal, status in zip(ids, statuses.status_list)
                                  if status.status not in TERMINAL}
            new = [status for goal, status in zip(ids, statuses.status_list)
                   if goal not in known and goal in self._seen_active]
            if new:
                self._watched_status = max(new, key=lambda status: (
                    status.goal_info.stamp.sec, status.goal_info.stamp.nanosec)).status
        self._statuses = statuses

    def _status_of_new_goal(self) -> int | None:
        """The watched goal_pose goal's status (_on_status), or None."""
        return None if self._known_goals is None else self._watched_status

    @property
    def navigation_ended(self) -> bool:
        """True when the stack ended the current goal itself (succeeded, aborted or
        canceled): it no longer drives the robot. A NavigateToPose goal of ours ends with its
        result; a goal_pose one when the goal bt_navigator made of it ended, unless a newer
        one is under way (which also covers our action goal preempted by that one)."""
        watched = self._status_of_new_goal()
        if watched is not None and watched not in TERMINAL:
            return False
        if self._result_future is not None:
            return self._result_future.done()
        return watched is not None

    def finish(self, timeout: float) -> str:
        """End the episode's NavigateToPose goal: cancel it if the stack still pursues it.
        Returns a note on how the navigation ended ('' when nothing says)."""
        if self._goal_handle is None:
            watched = self._status_of_new_goal()
            self._known_goals = None
            if watched not in TERMINAL:
                return ''
            name = self.node.resolve_topic_name(NAVIGATE_ACTION)
            return f'{name} goal {TERMINAL[watched]} by the stack (seen on its status topic)'
        name = self.node.resolve_topic_name(NAVIGATE_ACTION)
        try:
            if not self.navigation_ended:
                # Wait for the goal to end, not only for the cancel to be accepted: the stack
                # has stopped navigating before the next episode resets it.
                deadline = time.monotonic() + timeout
                cancel = self._goal_handle.cancel_goal_async()
                if (self._wait_until(cancel.done, deadline)
                        and self._wait_until(self._result_future.done, deadline)):
                    return f'{name} goal still active at the end: canceled'
                return (f'{name} goal still active at the end; its cancel was not confirmed '
                        f'within {timeout:.1f} s wall time')
            response = self._result_future.result()
            status = TERMINAL.get(response.status, f'status {response.status}')
            note = f'{name} goal {status} by the stack'
            code = getattr(response.result, 'error_code', 0)
            if code:
                message = getattr(response.result, 'error_msg', '')
                note += f' (error {code}{": " + message if message else ""})'
            return note
        finally:
            self._goal_handle = self._result_future = None
            self._known_goals = None

    # ---- helpers ---------------------------------------------------------------------------

    def _wait_until(self, condition, deadline: float) -> bool:
        """Poll ``condition`` until it holds, the deadline passes or the worker stops."""
        while not condition():
            if time.monotonic() >= deadline or not self.running():
                return False
            time.sleep(POLL)
        return True


class FilingActionClient(ActionClient):
    """rclpy's ActionClient with each request filed before its answer can be handled.

    rclpy 7.1 (the Jazzy wheels pinned here) sends a goal, cancel or result request and only
    then files the request's future. An answer the executor thread takes in between is dropped
    ("Ignoring unexpected goal response. There may be more than one action server ...") and the
    future never completes (ros2/rclpy#1123, fixed upstream by rclpy#1308). Seen on a loaded
    machine: the stack accepted the goal and the episode still ended controller_unresponsive.
    Sending and filing hold a lock that the handling of answers waits for.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._filing = threading.Lock()

    def send_goal_async(self, *args: Any, **kwargs: Any):
        with self._filing:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle):
        with self._filing:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._filing:
            return super()._get_result_async(goal_handle)

    async def execute(self, taken_data):
        with self._filing:  # a request being sent now is filed before any answer is handled
            pass
        return await super().execute(taken_data)
