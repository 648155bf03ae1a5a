"""A test map can sit at any origin (a facility generator's maps sit at its training map's):
every pose moves with it and nothing else changes."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import MissionSpec
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import certify_environment, make_environment
from sessgan_gen.checkpoint import map_origin
from sessgan_gen.errors import CheckpointError

pytestmark = pytest.mark.unit


@pytest.mark.parametrize('mission, fleet', [(None, None), (MissionSpec(stations=2), None),
                                            (None, FleetSpec(robots=2))])
def test_every_pose_moves_with_the_origin(mission, fleet):
    cells = load_example_map('factory').cells
    home = make_environment(cells, 'factory', 'home', seed=5, mission=mission, fleet=fleet)
    moved = make_environment(cells, 'factory', 'moved', seed=5, mission=mission, fleet=fleet,
                             origin=(12.25, -40.5))
    assert home.feasible and moved.feasible
    assert moved.origin == (12.25, -40.5)
    assert np.array_equal(moved.occupancy, home.occupancy)
    assert moved.route_length == pytest.approx(home.route_length)
    assert moved.route_min_clearance == pytest.approx(home.route_min_clearance)
    pairs = [(home.start, moved.start), (home.goal, moved.goal),
             *zip(home.stations, moved.stations),
             *((a, b) for h, m in zip(home.fleet, moved.fleet)
               for a, b in ((h.start, m.start), (h.goal, m.goal)))]
    assert len(pairs) == 2 + len(home.stations) + 2 * len(home.fleet)
    for before, after in pairs:
        assert (after.x - before.x, after.y - before.y) == pytest.approx((12.25, -40.5))
        assert after.yaw == before.yaw
    moved.validate()
    # The certificate checked at the origin agrees with the one drawn there.
    assert certify_environment(moved) is not None
    # Moving a drawn environment there is drawing it there.
    shifted = home.moved_to((12.25, -40.5))
    assert (shifted.origin, shifted.start, shifted.goal, shifted.stations, shifted.fleet) == \
        (moved.origin, moved.start, moved.goal, moved.stations, moved.fleet)
    assert home.moved_to(home.origin) is home


def test_an_infeasible_map_puts_its_start_on_the_map_at_the_origin():
    cells = np.ones((16, 16), dtype=np.int64)  # all wall
    moved = make_environment(cells, 'factory', 'walled', origin=(-3.0, 7.0))
    assert not moved.feasible
    moved.validate()


def test_the_checkpoint_origin_defaults_to_zero_and_is_checked():
    assert map_origin({}) == (0.0, 0.0)
    assert map_origin({'map_origin': [1.5, -2.0, 0.3]}) == (1.5, -2.0)
    for bad in ([1.0], [1.0, float('nan'), 0.0], 'here', [True, 0.0]):
        with pytest.raises(CheckpointError, match='map_origin'):
            map_origin({'map_origin': bad})

