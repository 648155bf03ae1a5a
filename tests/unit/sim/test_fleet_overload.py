"""A clocked fleet episode that ends overloaded names every robot that could not keep pace."""

import pytest

pytest.importorskip('rclpy')  # sessgan_sim.worker is the node's side

from sessgan_sim.command_pace import PaceMonitor, PaceRule  # noqa: E402
from sessgan_sim.simulator_settings import SimulatorSettings  # noqa: E402
from sessgan_sim.worker.stepping import EpisodeStepper  # noqa: E402

pytestmark = pytest.mark.unit

TICK = 0.05


def commands(monitor: PaceMonitor, times) -> PaceMonitor:
    for time in times:
        monitor.command(round(time, 6))
    return monitor


def test_a_robot_not_yet_judged_mid_episode_is_named_when_another_ends_it():
    rule = PaceRule(expected_period=TICK)
    # r0 has run 12 s with one late gap of 1.4 s (12 %): judged and overloaded mid-episode.
    steady = [i * TICK for i in range(100)] + [6.4 + i * TICK for i in range(113)]
    # r1 started later: 6 s measured (under the 10 s before the share is judged mid-way),
    # late 0.8 s of every second.
    stalling = [start + 0.2 + i * TICK for start in range(6, 12) for i in range(4)]
    # r2 kept pace all along.
    paces = [commands(PaceMonitor(rule, TICK), times)
             for times in (steady, stalling, [i * TICK for i in range(240)])]
    assert paces[0].overload() is not None and paces[1].overload() is None
    detail = EpisodeStepper([None] * 3).overloads(paces, range(3), SimulatorSettings())
    assert 'robot r0: the stack could not keep pace' in detail
    assert 'robot r1: the stack could not keep pace' in detail
    assert 'robot r2' not in detail


def test_only_a_robot_that_ended_after_its_stack_fell_silent_is_noted():
    from types import SimpleNamespace

    rule = PaceRule(expected_period=TICK)
    # r0's stack fell silent at 2 s; r1's commanded to the end; r2's was told its navigation
    # ended (an explained gap); r3 reached its goal after its stack fell silent.
    paces = [commands(PaceMonitor(rule, TICK), [i * TICK for i in range(41)]),
             commands(PaceMonitor(rule, TICK), [i * TICK for i in range(240)]),
             commands(PaceMonitor(rule, TICK), [i * TICK for i in range(41)]),
             commands(PaceMonitor(rule, TICK), [i * TICK for i in range(41)])]
    paces[2].restart_gap()
    assert paces[0].silent_for(12.0) == pytest.approx(10.0) and paces[2].silent_for(12.0) is None
    ended = [SimpleNamespace(outcome=outcome, observation=SimpleNamespace(time=12.0))
             for outcome in ('stuck', 'stuck', 'timeout', 'goal_reached')]
    left: dict[int, float] = {}
    EpisodeStepper.note_left_robots(range(4), ended, paces, 10.0, left)
    assert left == {0: pytest.approx(10.0)}
    # Without a stuck rule there is no sim-time window to judge silence by.
    left.clear()
    EpisodeStepper.note_left_robots(range(4), ended, paces, 0.0, left)
    assert not left
