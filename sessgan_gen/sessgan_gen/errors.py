"""Errors raised by the sessgan_gen core (the GAN: checkpoints and sampling).

The errors of the shared modules (scenarios, maps, environments, missions, fleets) are
sessgan_core's (:mod:`sessgan_core.errors`); code that reports either catches both bases.
"""


class SessganGenError(Exception):
    """Base class of every error raised by sessgan_gen."""


class CheckpointError(SessganGenError):
    """A missing, corrupt or incompatible generator checkpoint."""


class SamplingRequestError(SessganGenError, ValueError):
    """A request the sampler cannot serve: absurd size, too many seeds or cells, unknown
    scenario."""
