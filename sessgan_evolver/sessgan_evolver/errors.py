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


class HarnessFailureError(CampaignError):
    """An episode the test harness (a silent controller, a dead process, a simulator that
    could not run it) ended on every one of its tries: no result can be recorded."""


class CellularAutomatonError(SessganEvolverError, ValueError):
    """Settings or a scenario the cellular automaton cannot work with."""


class FaultPictureError(SessganEvolverError):
    """A bag or run that holds too little to draw."""


class SearchError(SessganEvolverError):
    """A search that cannot run (no budget, a method that proposes nothing)."""


class FaultError(SessganEvolverError, ValueError):
    """A fault rule or a failure that cannot be keyed (bad cell sizes, no trace)."""


class FreshSeedError(SessganEvolverError):
    """A generator or run that cannot be evaluated, or seeds that are not fresh."""


class BagExportError(SessganEvolverError):
    """A trace that cannot become a bag (no scans kept, inconsistent lengths)."""


class CompareError(SessganEvolverError):
    """Settings a comparison cannot run with."""


class MapOperatorError(SessganEvolverError, ValueError):
    """Operator settings or parents that do not fit."""


class EpisodeRunnerError(SessganEvolverError):
    """An episode that cannot be run in process (unknown controller, bad settings)."""


class SearchMethodError(SessganEvolverError, ValueError):
    """A method name or setting that does not exist or does not fit."""


class ExternalWorkerError(SessganEvolverError):
    """An episode on an external worker gave nothing this process can use."""


class SuiteError(SessganEvolverError):
    """A regression suite that cannot be read or run as given (names the entry)."""


class BagCollectionError(SessganEvolverError):
    """A failure bag of a remote worker that could not be copied here intact (a transfer that
    failed, a file of another size or digest than episode.json records, an unsafe name)."""


def usage_errors() -> tuple[type[Exception], ...]:
    """What a command's config ``validate`` raises for an option it refuses: a usage error
    (exit 2). A function: sessgan_gen's errors are imported only when a command asks."""
    from sessgan_core.errors import SessganCoreError
    from sessgan_gen.errors import SessganGenError

    return (SessganEvolverError, SessganCoreError, SessganGenError, ValueError)
