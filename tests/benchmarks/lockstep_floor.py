"""The floor of lockstep messaging: bare rclpy, the reference episode's messages, no simulation.

``--role controller`` answers every scan with a Twist (use_sim_time on, so /clock is delivered
too; the executor, QoS and raw odometry of the built-in controllers); ``--role sim`` publishes
clock, odom and a 360-beam scan per tick with the simulator's QoS, waits for each answer on a
wait set as the simulator does, prints ``measuring`` after its warm-up and then
``ticks_per_second=<n> cpu_ms_per_tick=<its own CPU time a tick>``. Nothing of SESS-GAN is
imported: this is what any rclpy simulator/controller pair costs per tick on this machine, the
baseline that bench_simulator_node.py measures the real pair against.
"""

from __future__ import annotations

import argparse
import array
import time

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)  # the sim's
ANSWER_TIMEOUT = 30.0
"""Wall seconds a tick waits for its answer (best effort: a lost one would wait forever)."""


def controller() -> None:
    node = rclpy.create_node('floor_controller',
                             parameter_overrides=[Parameter('use_sim_time', value=True)])
    publisher = node.create_publisher(Twist, 'cmd_vel', 10)
    latest = {}

    def on_scan(msg: LaserScan) -> None:
        command = Twist()
        command.linear.x = 0.1 if 'odom' in latest else 0.0
        publisher.publish(command)

    node.create_subscription(Odometry, 'odom', lambda data: latest.update(odom=data), QOS,
                             raw=True)  # as the built-in controllers read it
    node.create_subscription(LaserScan, 'scan', on_scan, QOS)
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        rclpy.spin(node)
        return
    executor = EventsExecutor()
    executor.add_node(node)
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.5)


def sim(ticks: int) -> None:
    node = rclpy.create_node('floor_sim')
    clock = node.create_publisher(Clock, 'clock', QOS)
    odom = node.create_publisher(Odometry, 'odom', QOS)
    scan_publisher = node.create_publisher(LaserScan, 'scan', QOS)
    commands = node.create_subscription(Twist, 'cmd_vel', lambda _: None, COMMAND_QOS)
    wait_set = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, node.context.handle)
    deadline = time.monotonic() + 30.0
    while scan_publisher.get_subscription_count() == 0 or node.count_publishers('cmd_vel') == 0:
        if time.monotonic() > deadline:
            raise SystemExit('the floor controller did not come up')
        time.sleep(0.02)
    time.sleep(0.5)  # let the other readers (clock, odom) match too

    def tick(index: int) -> None:
        stamp_ns = index * 50_000_000
        message = Clock()
        message.clock.sec, message.clock.nanosec = divmod(stamp_ns, 1_000_000_000)
        clock.publish(message)
        pose = Odometry()
        pose.header.stamp = message.clock
        pose.header.frame_id = 'odom'
        odom.publish(pose)
        scan = LaserScan()
        scan.header.stamp = message.clock
        scan.header.frame_id = 'base_scan'
        scan.ranges = array.array('f', [5.0]) * 360
        scan_publisher.publish(scan)
        deadline = time.monotonic() + ANSWER_TIMEOUT
        while commands.handle.take_message(Twist, False) is None:
            if time.monotonic() > deadline:
                raise SystemExit(f'no cmd_vel answer to tick {index} within '
                                 f'{ANSWER_TIMEOUT:.0f} s')
            wait_set.clear_entities()
            wait_set.add_subscription(commands.handle)
            wait_set.wait(1_000_000_000)

    for index in range(100):  # warm-up
        tick(index)
    print('measuring', flush=True)  # the benchmark reads the controller's CPU time from here
    start, cpu_start = time.perf_counter(), time.process_time()
    for index in range(ticks):
        tick(100 + index)
    cpu = time.process_time() - cpu_start
    print(f'ticks_per_second={ticks / (time.perf_counter() - start):.1f} '
          f'cpu_ms_per_tick={cpu / ticks * 1e3:.4f}', flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--role', choices=('sim', 'controller'), required=True)
    parser.add_argument('--ticks', type=int, default=3000)
    args, ros_args = parser.parse_known_args()
    rclpy.init(args=ros_args)
    try:
        sim(args.ticks) if args.role == 'sim' else controller()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
