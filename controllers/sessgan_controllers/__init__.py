"""Robot-under-test controllers for SESS-GAN, each its own node speaking only the topic contract.

Cores (no ROS): :mod:`.nearness_diagram` (ground robot), :mod:`.velocity_projection`
(flyer), :mod:`.race_controller` (car), and :mod:`.reference_navigator` (a default Nav2
set-up for all three, on :mod:`.costmap`, :mod:`.path_planning` and
:mod:`.path_following`), sharing the types of :mod:`.controller_interface`; look them up
by name in :mod:`.registry`. Nodes: ``ros2 run sessgan_controllers <name>``, one executable per
registered core, all running :mod:`.controller_node` (scan, odom, goal_pose and, for cores
that plan, map in; cmd_vel out).
"""

__version__ = '0.1.0'
