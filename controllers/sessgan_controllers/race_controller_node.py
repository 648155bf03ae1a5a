"""The ``race_controller`` node: the follow-the-gap race controller for the car.

Run it with ``ros2 run sessgan_controllers race_controller``. It speaks the robot-under-test
contract (scan, odom, goal_pose in; cmd_vel out; see
:mod:`sessgan_controllers.controller_node`). Parameters: the fields of the controller's
config plus ``use_stamped_cmd_vel`` and ``base_frame_id``.
"""

from __future__ import annotations

from sessgan_controllers.controller_node import ControllerNode, run


class RaceControllerNode(ControllerNode):
    """The race_controller controller as a node."""

    controller_name = 'race_controller'


def main(args: list[str] | None = None) -> None:
    run(RaceControllerNode, args)


if __name__ == '__main__':
    main()
