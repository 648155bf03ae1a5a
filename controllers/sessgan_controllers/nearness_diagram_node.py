"""The ``nearness_diagram`` node: Nearness-Diagram navigation for the differential-drive robot.

Run it with ``ros2 run sessgan_controllers nearness_diagram``. It speaks the robot-under-test
contract (scan, odom, goal_pose in; cmd_vel out; see
:mod:`sessgan_controllers.controller_node`). Parameters: the fields of the controller's
config plus ``use_stamped_cmd_vel`` and ``base_frame_id``.
"""

from __future__ import annotations

from sessgan_controllers.controller_node import ControllerNode, run


class NearnessDiagramNode(ControllerNode):
    """The nearness_diagram controller as a node."""

    controller_name = 'nearness_diagram'


def main(args: list[str] | None = None) -> None:
    run(NearnessDiagramNode, args)


if __name__ == '__main__':
    main()
