"""Errors raised by the sessgan_core modules (scenarios, maps, environments, missions, fleets)."""


class SessganCoreError(Exception):
    """Base class of every error raised by sessgan_core."""


class UnknownScenarioError(SessganCoreError, KeyError):
    """A scenario name that is not in the registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class MapFormatError(SessganCoreError, ValueError):
    """A token map, PGM or YAML file that cannot be read or is malformed."""


class InvalidEnvironmentError(SessganCoreError, ValueError):
    """An environment (occupancy grid, resolution, start, goal) that cannot be simulated."""


class InvalidMissionError(SessganCoreError, ValueError):
    """A mission request that cannot be served: a negative or absurd number of stations, a
    negative or non-finite dwell time."""


class InvalidFleetError(SessganCoreError, ValueError):
    """A fleet request that cannot be served: a robot count outside 1..MAX_ROBOTS, or a fleet
    with mission stations."""
