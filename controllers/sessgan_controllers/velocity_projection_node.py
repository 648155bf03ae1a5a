"""The ``velocity_projection`` node: velocity-projection obstacle avoidance for the flyer.

Run it with ``ros2 run sessgan_controllers velocity_projection``. It speaks the robot-under-test
contract (scan, odom, goal_pose in; cmd_vel out; see
:mod:`sessgan_controllers.controller_node`). Parameters: the fields of the controller's
config plus ``use_stamped_cmd_vel`` and ``base_frame_id``.
"""

from __future__ import annotations

from sessgan_controllers.controller_node import ControllerNode, run


class VelocityProjectionNode(ControllerNode):
    """The velocity_projection controller as a node."""

    controller_name = 'velocity_projection'


def main(args: list[str] | None = None) -> None:
    run(VelocityProjectionNode, args)


if __name__ == '__main__':
    main()
