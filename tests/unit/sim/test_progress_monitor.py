"""The stuck rule on its own (sessgan_sim.progress): a corridor 1 m wide, the goal at its east
end, in 0.5 m certificate cells."""

import math

import numpy as np
import pytest

from sessgan_core.environment import Pose2D
from sessgan_core.route_certificate import CertificateGrid
from sessgan_sim.progress import ProgressMonitor, progress_field

pytestmark = pytest.mark.unit


def corridor():
    clearance = np.zeros((4, 10))
    clearance[1:3, 1:9] = 0.5  # free 1 m x 4 m inside walls
    grid = CertificateGrid(clearance, 1, 0.5, (0.0, 0.0), 1.0)
    return progress_field(grid, Pose2D(0.75, 0.75, 0.0), Pose2D(4.25, 0.75, 0.0),
                          feasible=False, footprint_radius=0.2, route_need=0.4)


def test_the_field_measures_the_distance_to_the_goal_along_free_cells():
    field = corridor()
    assert field.distance(4.25, 0.75) == 0.0
    assert field.distance(0.75, 0.75) == pytest.approx(3.5)
    assert field.distance(2.25, 1.25) == pytest.approx(2.0)  # a diagonal step counts as one
    assert field.distance(0.25, 0.25) == math.inf  # in the wall
    assert field.distance(-3.0, 0.75) == math.inf  # off the grid


def test_a_robot_without_a_new_least_distance_for_the_timeout_is_stuck():
    monitor = ProgressMonitor([corridor()], stuck_timeout=2.0)
    monitor.start_leg(0, 0.75, 0.75)
    def never():
        return False

    assert not monitor.stuck(1.0, 1.25, 0.75, never)  # progress at 1 s
    assert not monitor.stuck(2.9, 1.25, 0.75, never)
    assert not monitor.stuck(2.9, 0.75, 0.75, never)  # backing off is no progress, still 1.9 s
    assert monitor.stuck(3.0, 1.25, 0.75, never)


def test_new_ground_away_from_the_goal_is_progress_to_and_fro_is_not():
    """A planner's own way (a longer one, round an agent) first leads away from the goal: the
    robot is not stuck while it reaches ground it has not been on; going back over it, it is."""
    monitor = ProgressMonitor([corridor()], stuck_timeout=2.0)
    monitor.start_leg(0, 2.25, 0.75)
    def never():
        return False

    assert not monitor.stuck(1.5, 1.75, 0.75, never)  # away, onto a new 0.5 m square
    assert not monitor.stuck(3.0, 1.25, 0.75, never)  # further away, new again
    assert not monitor.stuck(4.5, 0.75, 0.75, never)
    # Back and forth over the squares it has covered: 2 s after the last new one, stuck.
    assert not monitor.stuck(5.5, 1.25, 0.75, never)
    assert not monitor.stuck(6.0, 1.75, 0.75, never)
    assert monitor.stuck(6.5, 1.25, 0.75, never)


def test_waiting_and_holding_are_not_being_stuck():
    monitor = ProgressMonitor([corridor()], stuck_timeout=2.0)
    monitor.start_leg(0, 0.75, 0.75)
    asked = []
    assert not monitor.stuck(5.0, 0.75, 0.75, lambda: asked.append(5.0) or True)
    assert asked == [5.0]
    assert not monitor.stuck(6.5, 0.75, 0.75, lambda: False)
    assert monitor.stuck(7.0, 0.75, 0.75, lambda: False)
    monitor.hold(7.0)  # e.g. dwelling at a station
    assert not monitor.stuck(8.0, 0.75, 0.75, lambda: False)
    # Progress is never asked about waiting.
    assert not monitor.stuck(8.5, 1.25, 0.75, lambda: pytest.fail('asked while progressing'))


def test_a_new_leg_measures_from_where_the_robot_is_and_a_zero_timeout_disables_the_rule():
    field = corridor()
    back = progress_field(field.grid, Pose2D(4.25, 0.75, 0.0), Pose2D(0.75, 0.75, 0.0),
                          feasible=False, footprint_radius=0.2, route_need=0.4)
    monitor = ProgressMonitor([field, back], stuck_timeout=2.0)
    monitor.start_leg(0, 0.75, 0.75)
    monitor.start_leg(1, 4.25, 0.75)
    assert monitor.best == pytest.approx(3.5)
    assert monitor.covered == {(8, 1)}  # the ground of leg 0 is forgotten
    assert not monitor.stuck(1.0, 3.75, 0.75, lambda: False)  # toward the new goal
    off = ProgressMonitor([field], stuck_timeout=0.0)
    off.start_leg(0, 0.75, 0.75)
    assert not off.stuck(1e6, 0.75, 0.75, lambda: pytest.fail('the rule is off'))
