"""SESS-GAN core: scenarios, token maps, environments, valid tests (route certificates, missions,
fleets), map_server files and the small helpers every package shares. No torch, no matplotlib;
rclpy and message types only in the ROS adapters (:mod:`.ros_conversion`, and lazily in
:mod:`.node_help` and :mod:`.ros_spin`).
"""

__version__ = '0.1.0'
