"""Errors raised by the sessgan_gen core."""


class SessganGenError(Exception):
    """Base class of every error raised by sessgan_gen."""


class UnknownScenarioError(SessganGenError, KeyError):
    """A scenario name that is not in the registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class MapFormatError(SessganGenError, ValueError):
    """A token map, PGM or YAML file that cannot be read or is malformed."""


class InvalidEnvironmentError(SessganGenError, ValueError):
    """An environment (occupancy grid, resolution, start, goal) that cannot be simulated."""


class CheckpointError(SessganGenError):
    """A missing, corrupt or incompatible generator checkpoint."""


class SamplingRequestError(SessganGenError, ValueError):
    """A request the sampler cannot serve: absurd size, too many seeds or cells, unknown
    scenario."""


class InvalidMissionError(SessganGenError, ValueError):
    """A mission request that cannot be served: a negative or absurd number of stations, a
    negative or non-finite dwell time."""


class InvalidFleetError(SessganGenError, ValueError):
    """A fleet request that cannot be served: a robot count outside 1..MAX_ROBOTS, or a fleet
    with mission stations."""
