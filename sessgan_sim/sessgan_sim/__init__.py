"""SESS-GAN simulator worker: pybullet world builder, robots, sensors, episode metrics and the
simulator node.
"""

__version__ = '0.1.0'
