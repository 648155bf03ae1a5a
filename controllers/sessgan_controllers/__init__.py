"""Robot-under-test controllers for SESS-GAN, each its own node speaking only cmd_vel/odom/scan/goal_pose."""

__version__ = '0.1.0'
