"""Registry of the built-in controllers: name -> config type and controller class.

Nodes, in-process episode runners (tests, benchmarks, the evolver's quick checks)
and users look a controller up here instead of importing a module by name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from sessgan_controllers.controller_interface import Controller
from sessgan_controllers.errors import UnknownControllerError
from sessgan_controllers.nearness_diagram import (
    NearnessDiagramConfig,
    NearnessDiagramController,
    TricycleNearnessDiagramConfig,
)
from sessgan_controllers.race_controller import RaceController, RaceControllerConfig
from sessgan_controllers.reference_navigator import (
    ReferenceNavigator,
    ReferenceNavigatorConfig,
)
from sessgan_controllers.velocity_projection import (
    VelocityProjectionConfig,
    VelocityProjectionController,
)


@dataclass(frozen=True)
class ControllerSpec:
    """One registered controller."""

    name: str
    """Also the ``ros2 run sessgan_controllers`` executable and the node's default name."""
    config_type: type
    """Dataclass whose fields are the controller's ROS parameters."""
    factory: Callable[[Any], Controller]
    """Builds the controller from a config instance."""
    robot: str
    """Robot model of sessgan_sim it is written for (its default one)."""
    description: str
    robots: tuple[str, ...] = ()
    """Every robot model it can drive, chosen with its ``robot`` parameter; empty: ``robot``
    only."""
    stands_in_for: tuple[str, ...] = ()
    """Scenario robot models its own ``robot`` replaces in a campaign (the tricycle is a
    factory robot like diff_drive, with the same footprint)."""

    def drives(self, robot: str) -> bool:
        """Whether it can drive sessgan_sim's robot model ``robot``."""
        return robot in (self.robots or (self.robot,))

    def robot_in(self, scenario_robot: str) -> str:
        """The robot model it drives in a scenario of ``scenario_robot``: its own where that
        stands in for the scenario's (the tricycle of tricycle_nearness_diagram in the
        factory), else the scenario's (which it may not be able to drive)."""
        return self.robot if scenario_robot in self.stands_in_for else scenario_robot

    def node_arguments(self, robot: str) -> list[str]:
        """ROS arguments that make its node drive ``robot`` (``-p robot:=...`` for a
        controller of several robots; none otherwise)."""
        return ['-p', f'robot:={robot}'] if self.robots and robot else []

    def make(self, config: Any = None, **overrides: Any) -> Controller:
        """A new controller from ``config`` (default config if None) with ``overrides``."""
        base = config if config is not None else self.config_type()
        return self.factory(replace(base, **overrides) if overrides else base)


CONTROLLERS: dict[str, ControllerSpec] = {}


def register_controller(spec: ControllerSpec) -> ControllerSpec:
    """Add a controller to the registry (users may register their own)."""
    CONTROLLERS[spec.name] = spec
    return spec


def get_controller(name: str) -> ControllerSpec:
    """Look a controller up by name; the error lists the known names."""
    try:
        return CONTROLLERS[name]
    except KeyError as err:
        raise UnknownControllerError(
            f'unknown controller {name!r}; known controllers: {", ".join(sorted(CONTROLLERS))}'
        ) from err


register_controller(ControllerSpec(
    name='nearness_diagram',
    config_type=NearnessDiagramConfig,
    factory=NearnessDiagramController,
    robot='diff_drive',
    description='Nearness-Diagram navigation (Minguez & Montano 2004) for the ground robot.',
))
register_controller(ControllerSpec(
    name='velocity_projection',
    config_type=VelocityProjectionConfig,
    factory=VelocityProjectionController,
    robot='flyer',
    description='Velocity-projection avoidance with a narrow field of view for the flyer.',
))
register_controller(ControllerSpec(
    name='race_controller',
    config_type=RaceControllerConfig,
    factory=RaceController,
    robot='car',
    description='Follow-the-gap track following with a reactive speed policy for the car.',
))
register_controller(ControllerSpec(
    name='reference_navigator',
    config_type=ReferenceNavigatorConfig,
    factory=ReferenceNavigator,
    robot='diff_drive',
    description='A default Nav2 set-up: A* on the map with inflation and scan marks, replanning, '
                'and a rotation shim + regulated pure pursuit (diff_drive), bicycle pure pursuit '
                'with a curvature speed profile (car) or holonomic pursuit (flyer).',
    robots=('diff_drive', 'car', 'flyer'),
))
register_controller(ControllerSpec(
    name='tricycle_nearness_diagram',
    config_type=TricycleNearnessDiagramConfig,
    factory=NearnessDiagramController,
    robot='tricycle',
    description='Nearness-Diagram navigation for the factory robot on a steered drive wheel, '
                'which cannot turn in place (turns no tighter than min_turn_radius).',
    stands_in_for=('diff_drive',),
))
