"""``cmd_vel`` read straight from a wait set, without an executor (lockstep speed)."""

from __future__ import annotations

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy

COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
"""cmd_vel: matches reliable and best-effort controllers; see CommandReceiver."""


class CommandReceiver:
    """Takes ``cmd_vel`` messages straight from a wait set, without an executor.

    Lockstep waits for one command per tick; an executor's Python overhead per wake-up costs
    more than the whole round trip, and the subscription's node is spun by nobody else. The
    reader is best effort: reliability's acknowledgements cost a fifth of a lockstep tick. An
    episode starts only once this reader has matched the controller's writer (a best-effort
    reader drops what comes before; see RobotChannel.wait_for_controller). A command lost on
    one host (none in bench_lockstep_under_load.py) would end the episode
    controller_unresponsive after the timeout, never hang it or shift later commands.
    """

    def __init__(self, parent, msg_type, topic: str = 'cmd_vel',
                 use_global_arguments: bool = True) -> None:
        """A reader of ``topic`` on a node of its own beside ``parent`` (same namespace and
        context); ``msg_type``: Twist or TwistStamped. ``use_global_arguments=False``: the
        process's remappings (its ``__ns``) do not apply, as for a fleet robot's node."""
        self.node = node = rclpy.create_node(
            parent.get_name() + '_cmd_vel', namespace=parent.get_namespace(),
            context=parent.context, use_global_arguments=use_global_arguments)
        self.msg_type = msg_type
        self.subscription = node.create_subscription(msg_type, topic, lambda _: None,
                                                     COMMAND_QOS)
        self.topic = node.resolve_topic_name(topic)
        self.context = node.context
        # A wait on a shut-down context never returns (seen with rclpy 7.1.6): shutdown (a
        # SIGTERM, say) wakes the waiting episode instead, as rclpy's executors wake theirs.
        self.shutdown = node.create_guard_condition(lambda: None)
        self.context.on_shutdown(self.shutdown.trigger)
        self.wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self.context.handle)
        self.stopped = False

    def stop(self) -> None:
        """End every wait, now and later: the worker is stopping (its episode is cut off)."""
        self.stopped = True
        self.shutdown.trigger()

    @property
    def running(self) -> bool:
        """False once stopped or once ROS is shut down."""
        return not self.stopped and self.context.ok()

    def take(self):
        """The oldest received command, or None."""
        taken = self.subscription.handle.take_message(self.subscription.msg_type, False)
        return None if taken is None else taken[0]

    def take_all(self) -> list:
        commands = []
        while (command := self.take()) is not None:
            commands.append(command)
        return commands

    def wait(self, timeout: float) -> bool:
        """Block until a command is ready or ``timeout`` seconds pass; False once stopped or
        ROS is shut down (no command will come)."""
        if not self.running:
            return False
        self.wait_set.clear_entities()
        self.wait_set.add_subscription(self.subscription.handle)
        self.wait_set.add_guard_condition(self.shutdown.handle)
        self.wait_set.wait(max(0, int(timeout * 1e9)))
        return self.running

    def matched_writers(self) -> int:
        """cmd_vel writers matched to this reader."""
        return self.subscription.get_publisher_count()

    def writers_in_graph(self) -> int:
        """cmd_vel writers discovery shows (matched or not)."""
        return self.node.count_publishers(self.topic)

    def mistyped_writers(self) -> list[str]:
        """The types of cmd_vel writers in the graph that this reader cannot match: Twist
        against TwistStamped, either way round (ROS 2 matches no reader to them and says
        nothing)."""
        mine = f'{self.msg_type.__module__.split(".")[0]}/msg/{self.msg_type.__name__}'
        return sorted({info.topic_type for info in self.node.get_publishers_info_by_topic(
            self.topic) if info.topic_type != mine})

    def writers_elsewhere(self) -> list[str]:
        """Other topics of the same last name (``/w1/cmd_vel`` beside this ``/w0/cmd_vel``)
        that have writers: a controller started under another namespace, most likely."""
        name = self.topic.rsplit('/', 1)[-1]
        return sorted(topic for topic, _ in self.node.get_topic_names_and_types()
                      if topic != self.topic and topic.rsplit('/', 1)[-1] == name
                      and self.node.count_publishers(topic))

    def destroy(self) -> None:
        self.node.destroy_node()
