"""The tf frame names of a simulated robot: the one contract the simulator's messages, the
bags exported from in-process episodes and the Nav2 worker's parameters share."""

MAP_FRAME = 'map'
ODOM_FRAME = 'odom'
BASE_FOOTPRINT = 'base_footprint'
BASE_LINK = 'base_link'
SCAN_FRAME = 'base_scan'
RANGE_DOWN_FRAME = 'base_range_down'
"""The flyer's downward range sensor: its x axis (the beam) points down."""
