"""The controller registry and the config dataclasses that become ROS parameters."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from sessgan_controllers.controller_interface import config_help
from sessgan_controllers.errors import InvalidConfigError, UnknownControllerError
from sessgan_controllers.registry import CONTROLLERS, get_controller

pytestmark = pytest.mark.unit


def test_the_built_in_controllers_are_registered():
    assert {name: spec.robot for name, spec in CONTROLLERS.items()} == {
        'nearness_diagram': 'diff_drive',
        'velocity_projection': 'flyer',
        'race_controller': 'car',
        'reference_navigator': 'diff_drive',
        'tricycle_nearness_diagram': 'tricycle',
    }
    assert get_controller('nearness_diagram').drives('diff_drive')
    assert not get_controller('nearness_diagram').drives('car')
    assert all(get_controller('reference_navigator').drives(robot)
               for robot in ('diff_drive', 'car', 'flyer'))


def test_a_controller_drives_the_scenario_robot_unless_its_own_stands_in_for_it():
    assert get_controller('reference_navigator').robot_in('car') == 'car'
    assert get_controller('nearness_diagram').robot_in('diff_drive') == 'diff_drive'
    # The tricycle controller brings its robot to the factory (campaigns start the
    # simulators with robot:=tricycle); a race car does not (it cannot drive that robot).
    assert get_controller('tricycle_nearness_diagram').robot_in('diff_drive') == 'tricycle'
    assert get_controller('race_controller').robot_in('diff_drive') == 'diff_drive'


def test_unknown_controller_lists_the_known_ones():
    with pytest.raises(UnknownControllerError, match='nearness_diagram'):
        get_controller('dwa')


@pytest.mark.parametrize('name', sorted(CONTROLLERS))
def test_config_fields_are_documented_ros_parameters(name):
    spec = get_controller(name)
    for item in dataclasses.fields(spec.config_type):
        assert type(item.default) in (float, int, bool, str), item.name
        assert config_help(spec.config_type)[item.name], f'{item.name} has no help text'
    spec.config_type().validate()


@pytest.mark.parametrize('name', sorted(CONTROLLERS))
def test_make_applies_overrides_and_validates(name):
    spec = get_controller(name)
    controller = spec.make(goal_tolerance=0.3)
    assert controller.config.goal_tolerance == 0.3
    controller.reset()
    with pytest.raises(InvalidConfigError, match='goal_tolerance'):
        spec.make(goal_tolerance=-1.0)


def test_every_registered_controller_has_an_executable_of_the_one_node():
    """setup.py installs one executable per registry name, each running controller_node.main
    (which picks the controller by the executable's name)."""
    setup = (Path(__file__).resolve().parents[3] / 'controllers' / 'setup.py').read_text()
    names = re.search(r'^controllers = \((.*?)\)', setup, re.MULTILINE | re.DOTALL).group(1)
    assert sorted(re.findall(r"'(\w+)'", names)) == sorted(CONTROLLERS)
    assert "f'{name} = sessgan_controllers.controller_node:main' for name in controllers" \
        in setup
