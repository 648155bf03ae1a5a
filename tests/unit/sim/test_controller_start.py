"""Before a lockstep episode's first tick the simulator waits for the controller's readers:
one that discovery has not shown yet must not be taken for one that does not exist."""

import time

import pytest

pytest.importorskip('rclpy')  # sessgan_sim.worker is the node's side

from sessgan_sim.worker.stepping import RobotChannel  # noqa: E402

pytestmark = pytest.mark.unit

TOPICS = ('clock', 'odom', 'scan')


class Discovery:
    """What discovery shows of a controller: its readers of the tick's topics (each matched
    ``delays[topic]`` wall seconds after the start; absent: never) and its cmd_vel writer."""

    def __init__(self, delays: dict[str, float]) -> None:
        self.started = time.monotonic()
        self.delays = delays
        self.names = {topic: topic for topic in TOPICS}
        self.node = self
        self.running = True

    def _shown(self, topic: str) -> int:
        delay = self.delays.get(topic)
        return int(delay is not None and time.monotonic() - self.started >= delay)

    # RobotTopics
    def readers(self, topic: str) -> int:
        return self._shown(topic)

    # the node
    def count_subscribers(self, topic: str) -> int:
        return self._shown(topic)

    # CommandReceiver
    def matched_writers(self) -> int:
        return 1

    def writers_in_graph(self) -> int:
        return 1


def started_after(discovery: Discovery, channel: RobotChannel | None = None
                  ) -> tuple[float, RobotChannel]:
    """(wall seconds until the first tick may go, the channel) of a start with ``discovery``
    (on ``channel``, default a new one)."""
    channel = channel or RobotChannel(discovery, discovery, 'Twist')  # type: ignore[arg-type]
    channel.topics = channel.commands = discovery  # type: ignore[assignment]
    discovery.started = time.monotonic()
    assert channel.wait_for_controller(timeout=5.0)
    return time.monotonic() - discovery.started, channel


def test_the_first_tick_waits_for_an_odometry_reader_discovered_after_the_scan_reader():
    discovery = Discovery({'scan': 0.0, 'clock': 0.0, 'odom': 0.3})
    waited, _ = started_after(discovery)
    assert discovery.readers('odom') == 1
    assert 0.3 <= waited < 0.9


def test_a_controller_without_an_odometry_reader_costs_the_settling_second_once():
    discovery = Discovery({'scan': 0.0})
    waited, channel = started_after(discovery)
    assert 1.0 <= waited < 1.5
    assert channel.expected_readers == set()
    waited, _ = started_after(discovery, channel)
    assert waited < 0.2


def test_a_restarted_controller_is_awaited_on_every_topic_it_read_before():
    _, channel = started_after(Discovery({'scan': 0.0, 'clock': 0.0, 'odom': 0.0}))
    assert channel.expected_readers == {'clock', 'odom'}
    later = Discovery({'scan': 0.0, 'odom': 0.0, 'clock': 0.4})
    waited, _ = started_after(later, channel)
    assert 0.4 <= waited < 0.9
