"""The ``reference_navigator`` node: a default Nav2 set-up (A* on the map, replanning, a path
follower per robot) as one controller.

Run it with ``ros2 run sessgan_controllers reference_navigator`` and pick the robot:
``--ros-args -p robot:=diff_drive`` (the default; the factory), ``car`` (the race track) or
``flyer`` (the drone area). It speaks the robot-under-test contract and plans on the ``map``
topic (see :mod:`sessgan_controllers.controller_node`). Against a lockstep simulator it answers
every scan (the default ``control_mode:=scan``); against a clocked one run it like Nav2's
controller server, on its own timer: ``-p control_mode:=timer -p control_rate_hz:=20.0 -p
use_sim_time:=true``. Parameters: the fields of
:class:`~sessgan_controllers.reference_navigator.ReferenceNavigatorConfig` plus
``use_stamped_cmd_vel``, ``base_frame_id``, ``control_mode`` and ``control_rate_hz``.
"""

from __future__ import annotations

from sessgan_controllers.controller_node import ControllerNode, run


class ReferenceNavigatorNode(ControllerNode):
    """The reference_navigator controller as a node."""

    controller_name = 'reference_navigator'


def main(args: list[str] | None = None) -> None:
    run(ReferenceNavigatorNode, args)


if __name__ == '__main__':
    main()
