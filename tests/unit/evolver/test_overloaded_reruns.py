"""An overloaded episode (clocked: the stack could not keep pace) is re-run, slower with
--adaptive-rtf, and never a result (sessgan_evolver.harness, regression_suite)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sessgan_evolver.errors import HarnessFailureError
from sessgan_evolver.harness import HarnessRetries, real_time_factor_scale
from sessgan_evolver.regression_suite import (
    Attempt,
    AttemptKind,
    ScenarioProgress,
    SuiteEntry,
    Verdict,
    classify,
)
from sessgan_sim.command_pace import MIN_REAL_TIME_FACTOR_SCALE, check_real_time_factor_scale

pytestmark = pytest.mark.unit

OVERLOADED = 'the stack could not keep pace with sim time: 31% of the time in late gaps'


def test_each_overloaded_try_halves_the_pace_down_to_the_floor():
    assert real_time_factor_scale(0) == 0.0  # the simulator's own pace
    assert [real_time_factor_scale(n) for n in (1, 2, 3, 4)] == [0.5, 0.25, 0.125, 0.0625]
    assert real_time_factor_scale(9) == MIN_REAL_TIME_FACTOR_SCALE == 1 / 16


def test_retries_slow_an_overloaded_episode_down_only_when_asked():
    retries = HarnessRetries(5, adaptive_rtf=True)
    assert retries.real_time_factor_scale('a') == 0.0
    retries.failed('a', 'map-a', 'overloaded', OVERLOADED)
    assert retries.real_time_factor_scale('a') == 0.5
    retries.failed('a', 'map-a', 'controller_unresponsive', 'no cmd_vel within 2.0 s')
    assert retries.real_time_factor_scale('a') == 0.5  # only overloaded tries slow it down
    retries.failed('a', 'map-a', 'overloaded', OVERLOADED)
    assert retries.real_time_factor_scale('a') == 0.25
    assert retries.real_time_factor_scale('b') == 0.0  # per episode
    retries.succeeded('a')
    assert retries.real_time_factor_scale('a') == 0.0
    plain = HarnessRetries(3)
    plain.failed('a', 'map-a', 'overloaded', OVERLOADED)
    assert plain.real_time_factor_scale('a') == 0.0


def test_the_rerun_is_logged_with_its_pace():
    lines: list[str] = []
    retries = HarnessRetries(3, lines.append, adaptive_rtf=True)
    retries.failed('a', 'map-a', 'overloaded', OVERLOADED)
    assert 'running it again at 0.5 x the real-time factor (try 2 of 3)' in lines[-1]


def test_overloaded_on_every_try_stops_the_run_saying_what_to_do():
    retries = HarnessRetries(2)
    retries.failed('a', 'map-a', 'overloaded', OVERLOADED)
    with pytest.raises(HarnessFailureError, match='could not keep pace with sim time on every '
                                                  'one of 2 tries of episode map-a') as error:
        retries.failed('a', 'map-a', 'overloaded', OVERLOADED)
    assert '--adaptive-rtf' in str(error.value)


@pytest.mark.parametrize('scale, expected', [(0.0, 1.0), (1.0, 1.0), (0.5, 0.5),
                                             (1 / 16, 1 / 16)])
def test_the_simulator_takes_a_goal_scale_in_its_range(scale, expected):
    assert check_real_time_factor_scale(scale) == expected


@pytest.mark.parametrize('scale', [2.0, 0.01, -0.5, math.nan])
def test_the_simulator_refuses_a_goal_scale_out_of_range(scale):
    with pytest.raises(ValueError, match='real_time_factor_scale'):
        check_real_time_factor_scale(scale)


def test_a_suite_attempt_that_ended_overloaded_is_no_result_and_slows_the_next():
    metrics = {'outcome': 'overloaded', 'detail': OVERLOADED, 'feasible': True,
               'fault_collisions': 4}
    assert classify(metrics) is AttemptKind.HARNESS
    entry = SuiteEntry(name='s', bag=Path('bag'), episode={})
    progress = ScenarioProgress(entry, results_wanted=1, harness_tries=3)
    progress.add(Attempt(AttemptKind.HARNESS, metrics))
    progress.add(Attempt(AttemptKind.HARNESS, {'outcome': 'controller_unresponsive'}))
    progress.add(Attempt(AttemptKind.HARNESS, metrics))
    assert progress.overloaded_in_a_row == 2
    assert progress.verdict is Verdict.ERROR  # three harness outcomes: never a fail
    after_a_result = ScenarioProgress(entry, results_wanted=2, harness_tries=3)
    after_a_result.add(Attempt(AttemptKind.HARNESS, metrics))
    after_a_result.add(Attempt(AttemptKind.PASS, {'outcome': 'goal_reached'}))
    assert after_a_result.overloaded_in_a_row == 0
    after_a_result.add(Attempt(AttemptKind.HARNESS, metrics))
    assert after_a_result.overloaded_in_a_row == 1


def test_adaptive_rtf_without_clocked_workers_is_refused_by_name():
    from sessgan_evolver.campaign import CampaignConfig
    from sessgan_evolver.comparison import CompareConfig
    from sessgan_evolver.errors import CampaignError, CompareError
    from sessgan_evolver.evaluate_cli import parse_args as evaluate_args
    from sessgan_evolver.suite_cli import parse_args as suite_args

    with pytest.raises(CampaignError, match='adaptive_rtf'):
        CampaignConfig(in_process=True, adaptive_rtf=True).validate()
    CampaignConfig(external=True, adaptive_rtf=True).validate()
    with pytest.raises(CompareError, match='adaptive_rtf needs external'):
        CompareConfig(adaptive_rtf=True).validate()
    for parse in (evaluate_args, lambda argv: suite_args(['suite.yaml', *argv])):
        with pytest.raises(SystemExit) as error:
            parse(['--adaptive-rtf'])
        assert error.value.code == 2
        assert parse(['--adaptive-rtf', '--external']).adaptive_rtf
