"""The follow-the-gap race controller on synthetic scans (1 m cells, a 5 m wide track)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import STOP, Goal, RobotState, ScanData
from sessgan_controllers.race_controller import RaceController, RaceControllerConfig

pytestmark = pytest.mark.unit

LONG_STRAIGHT = ('#' * 40,) + ('.' * 40,) * 5 + ('#' * 40,)
"""A 40 m straight, 5 m wide, open at both ends."""


def cast(scan_factory, state, grid, range_max=30.0):
    return scan_factory(state, grid, resolution=1.0, range_max=range_max, step=0.05)


def dead_end(length: int) -> tuple[str, ...]:
    """A straight 5 m wide track closed by a barrier ``length`` cells from its start."""
    return ('#' * 40,) + ('.' * length + '#' * (40 - length),) * 5 + ('#' * 40,)


def test_full_speed_on_a_long_straight(scan_factory):
    controller = RaceController()
    state = RobotState(2.0, 3.5, 0.0, vx=5.0)
    decision = controller.decide(cast(scan_factory, state, LONG_STRAIGHT), state, Goal(60.0, 3.5))
    assert decision.command.vx == pytest.approx(controller.config.max_speed)
    assert abs(decision.direction) < math.radians(10.0)


def test_slows_down_before_a_barrier(scan_factory):
    controller = RaceController()
    state = RobotState(2.0, 3.5, 0.0, vx=8.0)
    goal = Goal(60.0, 3.5)
    far = controller.decide(cast(scan_factory, state, dead_end(20)), state, goal)
    near = controller.decide(cast(scan_factory, state, dead_end(8)), state, goal)
    assert far.free_ahead == pytest.approx(18.0, abs=0.2)
    assert near.free_ahead == pytest.approx(6.0, abs=0.2)
    assert near.command.vx < far.command.vx
    assert near.command.vx == pytest.approx(controller.config.speed_gain * 6.0, rel=0.05)


LEFT_BEND = (('#' * 20,) + ('#' * 12 + '.' * 5 + '###',) * 12 + ('.' * 17 + '###',) * 5
             + ('#' * 20,))
"""A 5 m wide straight along y = 1..6 ending in a barrier at x = 17, where the track turns
left into a branch x = 12..17 going up to y = 18."""


def test_follows_a_left_bend(scan_factory):
    controller = RaceController()
    state = RobotState(10.0, 3.5, 0.0, vx=4.0)
    decision = controller.decide(cast(scan_factory, state, LEFT_BEND), state, Goal(14.5, 30.0))
    assert not decision.goal_in_sight
    assert decision.direction > 0.3 and decision.command.wz > 0.0
    assert decision.free_ahead == pytest.approx(7.0, abs=0.2)


def test_goal_bias_chooses_the_fork_towards_the_goal(scan_factory):
    # A wall dead ahead splits the track into equally open left and right branches.
    controller = RaceController()
    state = RobotState(0.0, 0.0, 0.0, vx=3.0)
    island = [(12.0, y, 0.5) for y in np.arange(-4.0, 4.01, 0.5)]
    outer = [(x, side * 9.0, 0.5) for x in np.arange(-2.0, 30.0, 0.5) for side in (-1, 1)]
    scan = scan_factory(state, discs=island + outer, range_max=30.0, step=0.05)
    left = controller.decide(scan, state, Goal(25.0, 6.0))
    right = controller.decide(scan, state, Goal(25.0, -6.0))
    assert left.direction > 0.0 > right.direction


def test_heads_straight_for_a_goal_in_sight(scan_factory):
    controller = RaceController()
    state = RobotState(2.0, 3.5, 0.0, vx=5.0)
    goal = Goal(12.0, 4.5)
    decision = controller.decide(cast(scan_factory, state, LONG_STRAIGHT), state, goal)
    assert decision.goal_in_sight
    assert decision.direction == pytest.approx(math.atan2(1.0, 10.0))


def test_a_gap_narrower_than_the_car_is_not_open(scan_factory):
    # A barrier across the track with a 0.8 m slot: too narrow for the 1.2 m wide footprint.
    controller = RaceController()
    state = RobotState(0.0, 0.0, 0.0, vx=2.0)
    barrier = [(6.0, y, 0.25) for y in np.arange(-8.0, 8.01, 0.25) if abs(y) > 0.6]
    decision = controller.decide(
        scan_factory(state, discs=barrier, range_max=30.0, step=0.05), state, Goal(20.0, 0.0))
    assert decision.direction is None or abs(decision.direction) > math.radians(5.0)


def test_stops_with_nothing_open_ahead():
    controller = RaceController()
    boxed_in = ScanData(np.full(360, 1.0), -math.pi, math.radians(1.0), 0.05, 30.0)
    state = RobotState(0.0, 0.0, 0.0, vx=1.0)
    assert controller.decide(boxed_in, state, Goal(50.0, 0.0)).command == STOP


def test_speed_is_capped_in_a_turn():
    config = RaceControllerConfig()
    controller = RaceController(config)
    # Open everywhere: the goal is in sight 60 degrees to the left, far away.
    empty = ScanData(np.full(360, np.inf), -math.pi, math.radians(1.0), 0.05, 30.0)
    state = RobotState(0.0, 0.0, 0.0, vx=6.0)
    decision = controller.decide(empty, state, Goal(10.0, 17.3))
    assert decision.command.vx == pytest.approx(
        math.sqrt(config.max_lateral_acceleration / abs(decision.curvature)))
    assert decision.command.wz == pytest.approx(decision.command.vx * decision.curvature)


def test_stops_at_the_goal():
    controller = RaceController()
    empty = ScanData(np.full(360, np.inf), -math.pi, math.radians(1.0), 0.05, 30.0)
    assert controller.compute_command(empty, RobotState(0.0, 0.0, 0.0), Goal(0.5, 0.0)) == STOP


def test_rejects_bad_config():
    with pytest.raises(ValueError, match='min_speed'):
        RaceController(RaceControllerConfig(min_speed=20.0))
