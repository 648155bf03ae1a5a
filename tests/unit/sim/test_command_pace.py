"""The clocked-mode pace rule (sessgan_sim.command_pace) on hand-made arrival times."""

from __future__ import annotations

import pytest

from sessgan_sim.command_pace import PaceMonitor, PaceRule
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.metrics import HARNESS_OUTCOMES, Outcome, is_controller_failure
from sessgan_sim.simulator_settings import SimulatorSettings

pytestmark = pytest.mark.unit

TICK = 0.05


def feed(monitor: PaceMonitor, times) -> None:
    for time in times:
        monitor.command(round(time, 6))


def ticks(start: float, stop: float, step: float = TICK) -> list[float]:
    count = int(round((stop - start) / step))
    return [start + index * step for index in range(count)]


def test_a_stack_on_its_rate_with_jitter_keeps_pace():
    monitor = PaceMonitor(PaceRule(), TICK)
    # 20 Hz with every fifth command a tick late (gaps of 2 ticks, never over 3 periods)
    times = [time + (TICK if index % 5 == 4 else 0.0)
             for index, time in enumerate(ticks(0.0, 30.0))]
    feed(monitor, sorted(set(times)))
    figures = monitor.figures
    assert figures.period == pytest.approx(TICK) and not figures.declared
    assert figures.late_gaps == 0 and figures.late_time == 0.0
    assert monitor.overload() is None and monitor.overload(final=True) is None


def test_the_observed_period_is_the_median_of_the_first_gaps_floored_at_the_tick():
    monitor = PaceMonitor(PaceRule(observed_gaps=4), TICK)
    feed(monitor, [0.0, 0.1, 0.2, 0.3])
    assert monitor.figures.period is None  # 3 gaps: still observing
    monitor.command(0.5)
    assert monitor.figures.period == pytest.approx(0.1)  # median of 0.1, 0.1, 0.1, 0.2
    fast = PaceMonitor(PaceRule(observed_gaps=2), TICK)
    feed(fast, [0.0, 0.01, 0.02])  # finer than the simulator's tick
    assert fast.figures.period == pytest.approx(TICK)


def test_late_gaps_above_the_share_make_an_overload_with_the_figures():
    # 10 Hz declared; every second a 0.4 s gap (4 periods > 3): 0.4 of each 1.0 s late
    monitor = PaceMonitor(PaceRule(expected_period=0.1), TICK)
    times: list[float] = []
    for second in range(25):
        times += [second + 0.1 * step for step in range(7)]  # 0.0 .. 0.6, then 1.0
    feed(monitor, times[:7 * 19])
    assert monitor.overload() is None  # 18.6 s: under 200 periods, not judged yet
    feed(monitor, times[7 * 19:] + [25.0])
    figures = monitor.figures
    assert figures.declared and figures.period == pytest.approx(0.1)
    assert figures.late_gaps == 25
    assert figures.late_time == pytest.approx(10.0)
    assert figures.measured_time == pytest.approx(25.0)
    assert figures.late_share == pytest.approx(0.4)
    assert figures.longest_gap == pytest.approx(0.4)
    detail = monitor.overload()  # 25 s >= 200 periods: judged during the episode
    assert detail is not None
    assert '40% of the time in late gaps' in detail and 'declared' in detail
    assert '25 gap(s)' in detail and 'longest 0.40 s' in detail
    assert figures.summary() == ('period 0.100 s, 25 late gaps, 40.0% of 25.0 sim s late, '
                                 'longest gap 0.40 s')
    assert PaceMonitor(PaceRule(), TICK).figures.summary().startswith('period not measured')


def test_a_gap_of_exactly_the_factor_is_not_late():
    monitor = PaceMonitor(PaceRule(expected_period=0.1), TICK)
    feed(monitor, [0.0, 0.3, 0.6, 0.9])  # 3 periods each: not more than gap_factor
    assert monitor.figures.late_gaps == 0
    monitor.command(1.25)
    assert monitor.figures.late_gaps == 1


def test_the_share_is_judged_during_the_episode_only_after_enough_time_and_at_its_end():
    monitor = PaceMonitor(PaceRule(expected_period=0.1), TICK)
    feed(monitor, [0.0, 0.1, 0.2, 0.6, 0.7])  # 0.4 late of 0.7 s measured, 7 periods < 40
    assert monitor.overload() is None
    assert monitor.overload(final=True) is not None


def test_one_long_gap_is_an_overload_at_once():
    monitor = PaceMonitor(PaceRule(expected_period=0.05), TICK)
    feed(monitor, ticks(0.0, 1.0))
    assert monitor.overload() is None
    monitor.command(3.5)  # 2.55 s blind: over 40 periods (2.0 s)
    detail = monitor.overload()
    assert detail is not None and 'a gap of 2.55 sim s' in detail


def test_a_short_late_share_below_the_limit_is_no_overload():
    monitor = PaceMonitor(PaceRule(expected_period=0.05), TICK)
    times = ticks(0.0, 10.0)
    times = [time for time in times if not 5.0 < time < 5.5]  # one 0.5 s gap in 10 s
    feed(monitor, times)
    assert monitor.figures.late_gaps == 1
    assert monitor.figures.late_share == pytest.approx(0.5 / 9.95)
    assert monitor.overload(final=True) is None


def test_silence_is_not_lateness_the_open_gap_is_never_counted():
    # a controller that stops publishing (at its goal, or silent): no closed gap, no overload;
    # a silent one is controller_unresponsive by the wall-clock rule instead
    monitor = PaceMonitor(PaceRule(expected_period=0.05), TICK)
    feed(monitor, ticks(0.0, 2.0))
    assert monitor.overload(final=True) is None
    assert monitor.figures.late_gaps == 0


def test_a_restarted_gap_is_not_late():
    monitor = PaceMonitor(PaceRule(expected_period=0.05), TICK)
    feed(monitor, ticks(0.0, 2.0))
    monitor.restart_gap()  # the stack was told its navigation ended, or got a new goal
    feed(monitor, ticks(5.0, 7.0))
    figures = monitor.figures
    assert figures.late_gaps == 0 and figures.longest_gap == pytest.approx(TICK)
    assert figures.measured_time == pytest.approx(2 * (2.0 - TICK))
    assert monitor.overload(final=True) is None


def test_a_pause_after_a_stop_is_not_late_a_gap_while_driving_is():
    # Nav2's Wait recovery: a stop, 5 s of nothing, then 20 Hz again.
    paused = PaceMonitor(PaceRule(), TICK)
    feed(paused, ticks(0.0, 3.0))
    paused.command(3.0, stop=True)
    assert paused.paused and paused.silent_for(8.0) == pytest.approx(5.0)
    feed(paused, ticks(8.0, 12.0))
    assert paused.figures.late_gaps == 0 and paused.overload(final=True) is None
    # The same gap after a command that drove the robot: it drove blind for 5 s.
    blind = PaceMonitor(PaceRule(), TICK)
    feed(blind, ticks(0.0, 3.05) + ticks(8.0, 12.0))
    assert blind.figures.late_gaps == 1 and 'a gap of 5.00 sim s' in blind.overload()
    # Only the latest command of a tick counts: a stop then a drive is no pause.
    mixed = PaceMonitor(PaceRule(), TICK)
    feed(mixed, ticks(0.0, 3.0))
    mixed.command(3.0, stop=True)
    mixed.command(3.0, stop=False)
    feed(mixed, ticks(8.0, 12.0))
    assert mixed.figures.late_gaps == 1


def test_commands_in_one_tick_are_one_arrival():
    monitor = PaceMonitor(PaceRule(observed_gaps=2), TICK)
    feed(monitor, [0.0, 0.0, 0.05, 0.05, 0.1])
    assert monitor.figures.arrivals == 3
    assert monitor.figures.period == pytest.approx(TICK)


def test_gaps_seen_while_observing_are_judged_once_the_period_is_known():
    monitor = PaceMonitor(PaceRule(observed_gaps=5, late_share=0.2), TICK)
    # one 0.5 s gap among the first five, then regular: the median ignores it
    feed(monitor, [0.0, 0.05, 0.55, 0.6, 0.65, 0.7])
    figures = monitor.figures
    assert figures.period == pytest.approx(TICK)
    assert figures.late_gaps == 1 and figures.late_time == pytest.approx(0.5)
    assert monitor.overload(final=True) is not None  # 0.5 of 0.7 s


@pytest.mark.parametrize('values, name', [
    ({'expected_command_period': -0.1}, 'expected_command_period'),
    ({'overload_gap_factor': 1.0}, 'overload_gap_factor'),
    ({'overload_late_share': 0.0}, 'overload_late_share'),
    ({'overload_late_share': 1.5}, 'overload_late_share'),
])
def test_bad_pace_settings_are_refused_by_name(values, name):
    with pytest.raises(InvalidConfigError, match=name):
        SimulatorSettings.from_values(values)


def test_the_settings_build_the_rule():
    settings = SimulatorSettings.from_values({'expected_command_period': 0.1,
                                              'overload_gap_factor': 4.0,
                                              'overload_late_share': 0.3})
    rule = settings.pace_rule()
    assert (rule.expected_period, rule.gap_factor, rule.late_share) == (0.1, 4.0, 0.3)


def test_overloaded_is_a_harness_outcome_never_a_controller_failure():
    assert Outcome.OVERLOADED in HARNESS_OUTCOMES

    class Row:
        feasible = True
        fault_collisions = 3
        outcome = 'overloaded'

    assert not is_controller_failure(Row())
