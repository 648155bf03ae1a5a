"""Robot-under-test controllers for SESS-GAN, each its own node speaking only the topic contract.

Cores (no ROS): :mod:`.nearness_diagram` (ground robot), :mod:`.velocity_projection`
(flyer), :mod:`.race_controller` (car), sharing the types of :mod:`.types`; look them up
by name in :mod:`.registry`. Nodes: ``ros2 run sessgan_controllers <name>``, one executable
per registered core, all running :mod:`.controller_node` (scan, odom, goal_pose in; cmd_vel
out).
"""

__version__ = '0.1.0'
