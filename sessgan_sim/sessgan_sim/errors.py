"""Errors raised by the sessgan_sim core."""


class SessganSimError(Exception):
    """Base class of every error raised by sessgan_sim."""


class UnknownRobotError(SessganSimError, KeyError):
    """A robot model name that is not in the robot registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class InvalidConfigError(SessganSimError, ValueError):
    """A configuration value (rates, limits, sensor or robot parameters) that cannot work."""


class WorldError(SessganSimError):
    """A pybullet world used while closed, or that failed to build."""


class EpisodeError(SessganSimError):
    """An episode driven out of order: stepped before reset, after it ended, or while closed."""


class BagWriteError(SessganSimError):
    """A failure bag that cannot be written (bad record, unknown type, unsafe name, file
    system)."""


class BagServeError(SessganSimError):
    """A request for a failure bag's files that cannot be served (an unsafe or unknown bag, a
    file not of the bag, a chunk too large)."""
