"""Errors raised by the sessgan_evolver core."""


class SessganEvolverError(Exception):
    """Base class of every error raised by sessgan_evolver."""


class GenomeError(SessganEvolverError, ValueError):
    """A genome that is malformed, incompatible with another one, or unreadable bytes."""


class AlgorithmStateError(SessganEvolverError):
    """The genetic algorithm was used out of order (tell before ask, a member told twice,
    a wrong number of fitnesses) or given a state dict it cannot restore."""


class FitnessError(SessganEvolverError, ValueError):
    """Episode results or environment metrics that a fitness cannot be computed from."""


class RunStoreError(SessganEvolverError):
    """A run directory, checkpoint or metrics file that is missing, corrupt or inconsistent."""


class BagReadError(SessganEvolverError):
    """A failure bag that is missing, incomplete or corrupt."""


class ReportError(SessganEvolverError):
    """A report that cannot be written from the run's metrics."""


class CampaignError(SessganEvolverError):
    """A campaign cannot go on (no workers, a generator that refuses, bad settings)."""
