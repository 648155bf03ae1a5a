"""Shared fixtures: ROS isolation for the whole run and real node processes for graph tests."""

from __future__ import annotations

import os
import random

# Every test run keeps DDS traffic on this machine, in a domain of its own, so parallel runs
# (and other ROS users of the machine) never see each other. Child processes inherit this.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
if not os.environ.get('ROS_DOMAIN_ID'):
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randrange(10, 100))
os.environ.setdefault('PYTHONUNBUFFERED', '1')
# Servers wait for a client still being discovered before they answer (the profile's comment).
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config',
    'fastdds_profiles.xml'))

# UDP only, as setup.bash: tests kill processes, and a killed process's shared-memory port
# could leave later processes deaf to each other.
os.environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')

pytest_plugins = ['tests.ros_processes']
