"""Episodes the test harness ended, not the controller under test: run again, never recorded.

sessgan_sim.metrics.HARNESS_OUTCOMES names the outcomes that are no test result (a controller
that sent nothing in time, an episode cut off, a simulator that could not run it); a dead
simulator or controller process is the other harness failure. Under load such an episode
says how busy the machine was, not how the controller drives: recorded, it changed members'
fitness (4 of 48 episodes of a campaign at load 10-12 on 2 cores; the same episodes reach the
goal in a repeat). So campaigns, ``evaluate`` and ``compare`` run it again and count the
re-run (:class:`HarnessRetries`); it never reaches metrics, fitness, failure bags or figures.

An episode the harness ends on each of its ``tries`` stops the run (HarnessFailureError; a
campaign exits 1 with its --resume hint) rather than quarantining a worker: every worker runs
the same controller, so a controller silent on one map on several tries is most likely silent
on any worker, and a campaign that dropped the episode or went on without it would select on
fewer results than it reports. Stopping says so at once; --resume continues from the
generation's checkpoint when the cause is fixed.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

from sessgan_evolver.errors import HarnessFailureError
from sessgan_sim.metrics import Outcome

DEFAULT_HARNESS_TRIES = 3
"""Tries of one episode before a harness that fails on every one stops the run."""
MAX_HARNESS_TRIES = 20
"""The most tries a user may ask for (each can take a whole episode timeout)."""


def check_harness_tries(tries: object) -> int:
    """``tries`` as an int in [1, MAX_HARNESS_TRIES], else HarnessFailureError naming it."""
    if isinstance(tries, bool) or not isinstance(tries, int) \
            or not 1 <= tries <= MAX_HARNESS_TRIES:
        raise HarnessFailureError(f'harness_tries must be an integer in [1, '
                                  f'{MAX_HARNESS_TRIES}], got {tries!r}')
    return tries


class HarnessRetries:
    """Counts the harness failures of each episode and of the whole run.

    ``failed`` is called for every harness failure of an episode; it returns normally when
    the episode is to run again and raises HarnessFailureError on its ``tries``-th failure.
    ``succeeded`` forgets an episode once it has a result. ``reruns``: harness failures
    so far (each one an episode run again or, for the last, a stopped run).
    """

    def __init__(self, tries: int = DEFAULT_HARNESS_TRIES,
                 log: Callable[[str], None] | None = None) -> None:
        self.tries = check_harness_tries(tries)
        self.log = log
        self.reruns = 0
        self._failures: dict[Hashable, list[tuple[str, str]]] = {}

    def failed(self, key: Hashable, episode: str, outcome: str, detail: str) -> None:
        """Record that the harness ended episode ``key`` (named ``episode`` in messages):
        ``outcome`` a harness outcome or a short cause ('worker process died'), ``detail``
        what happened."""
        failures = self._failures.setdefault(key, [])
        failures.append((str(outcome), str(detail)))
        self.reruns += 1
        if len(failures) < self.tries:
            if self.log is not None:
                self.log(f'episode {episode}: {outcome} ({detail}): a harness failure, not a '
                         f'result; running it again (try {len(failures) + 1} of {self.tries})')
            return
        del self._failures[key]
        if all(cause == Outcome.CONTROLLER_UNRESPONSIVE for cause, _ in failures):
            raise HarnessFailureError(
                f'the controller under test was silent on every one of {len(failures)} tries '
                f'of episode {episode} ({Outcome.CONTROLLER_UNRESPONSIVE.value}; last: '
                f'{failures[-1][1]}); no result is recorded for it. Check that the '
                'controller runs and answers every scan (its log), or give the machine less '
                'other work')
        causes = '; '.join(f'{cause}: {detail}' for cause, detail in failures)
        raise HarnessFailureError(f'the test harness failed on every one of {len(failures)} '
                                  f'tries of episode {episode}, so it has no result: {causes}')

    def succeeded(self, key: Hashable) -> None:
        """Forget the harness failures of episode ``key`` (it has a result now)."""
        self._failures.pop(key, None)
