"""The simulator worker's evaluate feedback: every FEEDBACK_PERIOD of sim time and at least
FEEDBACK_WALL_PERIOD of wall time apart, so a fast lockstep episode does not spend its ticks on
feedback nobody can follow."""

import pytest

pytest.importorskip('rclpy')  # sessgan_sim.worker is the node's side

from sessgan_sim.worker.stepping import FEEDBACK_WALL_PERIOD, FeedbackSchedule  # noqa: E402

pytestmark = pytest.mark.unit


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def feedback_times(tick: float, wall_per_tick: float, ticks: int) -> list[float]:
    clock = FakeClock()
    schedule = FeedbackSchedule(clock)
    sent = []
    for index in range(1, ticks + 1):
        clock.now += wall_per_tick
        if schedule.due(index * tick):
            sent.append(round(index * tick, 9))
    return sent


def test_real_time_episode_gets_feedback_every_period_of_sim_time():
    # 20 Hz control at real time: as before, every fifth tick, also with ticks 10 % short.
    expected = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0]
    assert feedback_times(0.05, 0.05, 40) == expected
    assert feedback_times(0.05, 0.045, 40) == expected


def test_fast_episode_gets_feedback_every_period_of_wall_time():
    # 50x real time: 1 ms a tick, so about 200 ticks (10 sim s) between feedback messages.
    sent = feedback_times(0.05, 0.001, 1000)
    assert sent[0] == 0.25
    gaps = [later - earlier for earlier, later in zip(sent, sent[1:])]
    assert len(sent) == 5
    assert all(abs(gap - FEEDBACK_WALL_PERIOD / 0.001 * 0.05) <= 0.05 + 1e-9 for gap in gaps)
