"""Errors raised by the sessgan_controllers cores."""


class SessganControllersError(Exception):
    """Base class of every error raised by sessgan_controllers."""


class InvalidConfigError(SessganControllersError, ValueError):
    """A controller parameter out of its range (the message names it)."""


class UnknownControllerError(SessganControllersError, KeyError):
    """A controller name that is not in the registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class PlanningError(SessganControllersError, ValueError):
    """No path: the message says why."""
