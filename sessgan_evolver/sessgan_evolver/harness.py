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

An episode that ended ``overloaded`` (clocked mode: the stack could not keep pace with sim
time, sessgan_sim.command_pace) is run again like the others; with ``adaptive_rtf`` each such
re-run asks the simulator for half the real-time factor of the try before
(:func:`real_time_factor_scale`, at least sessgan_sim's MIN_REAL_TIME_FACTOR_SCALE).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

from sessgan_evolver.errors import HarnessFailureError
from sessgan_sim.command_pace import MIN_REAL_TIME_FACTOR_SCALE
from sessgan_sim.metrics import Outcome

DEFAULT_HARNESS_TRIES = 3
"""Tries of one episode before a harness that fails on every one stops the run."""
MAX_HARNESS_TRIES = 20
"""The most tries a user may ask for (each can take a whole episode timeout)."""

SINGLE_CAUSE_ADVICE: dict[str, tuple[str, str]] = {
    Outcome.OVERLOADED.value: (
        'the stack under test could not keep pace with sim time',
        "Give the machine less other work, lower the simulators' real_time_factor, or pass "
        '--adaptive-rtf (each re-run at half the pace)'),
    Outcome.CONTROLLER_UNRESPONSIVE.value: (
        'the controller under test was silent',
        'Check that the controller runs and answers every scan (its log); that a stack on '
        'sim time under a namespace reads its clock and tf there (-r /clock:=clock -r '
        '/tf:=tf -r /tf_static:=tf_static: /clock and /tf are absolute names); or give the '
        'machine less other work'),
}
"""What stopped an episode whose every try ended with one of these outcomes, and what to do
about it (the HarnessFailureError's message)."""


def check_harness_tries(tries: object) -> int:
    """``tries`` as an int in [1, MAX_HARNESS_TRIES], else HarnessFailureError naming it."""
    if isinstance(tries, bool) or not isinstance(tries, int) \
            or not 1 <= tries <= MAX_HARNESS_TRIES:
        raise HarnessFailureError(f'harness_tries must be an integer in [1, '
                                  f'{MAX_HARNESS_TRIES}], got {tries!r}')
    return tries


def real_time_factor_scale(overloaded_tries: int) -> float:
    """The evaluate goal's ``real_time_factor_scale`` for a re-run after ``overloaded_tries``
    overloaded tries: halved for each, never below MIN_REAL_TIME_FACTOR_SCALE; 0
    (the simulator's own pace) when there was none."""
    if overloaded_tries <= 0:
        return 0.0
    return max(0.5 ** overloaded_tries, MIN_REAL_TIME_FACTOR_SCALE)


class HarnessRetries:
    """Counts the harness failures of each episode and of the whole run.

    ``failed`` is called for every harness failure of an episode; it returns normally when
    the episode is to run again and raises HarnessFailureError on its ``tries``-th failure.
    ``succeeded`` forgets an episode once it has a result. ``reruns``: harness failures
    so far (each one an episode run again or, for the last, a stopped run). With
    ``adaptive_rtf``, :meth:`real_time_factor_scale` slows the re-runs of an overloaded
    episode down.
    """

    def __init__(self, tries: int = DEFAULT_HARNESS_TRIES,
                 log: Callable[[str], None] | None = None, adaptive_rtf: bool = False) -> None:
        self.tries = check_harness_tries(tries)
        self.log = log
        self.adaptive_rtf = adaptive_rtf
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
                scale = self.real_time_factor_scale(key)
                pace = f' at {scale:g} x the real-time factor' if scale else ''
                self.log(f'episode {episode}: {outcome} ({detail}): a harness failure, not a '
                         f'result; running it again{pace} (try {len(failures) + 1} of '
                         f'{self.tries})')
            return
        del self._failures[key]
        distinct = {cause for cause, _ in failures}
        if len(distinct) == 1 and (only := distinct.pop()) in SINGLE_CAUSE_ADVICE:
            what, advice = SINGLE_CAUSE_ADVICE[only]
            raise HarnessFailureError(
                f'{what} on every one of {len(failures)} tries of episode {episode} '
                f'({only}; last: {failures[-1][1]}); no result is recorded for it. {advice}')
        causes = '; '.join(f'{cause}: {detail}' for cause, detail in failures)
        raise HarnessFailureError(f'the test harness failed on every one of {len(failures)} '
                                  f'tries of episode {episode}, so it has no result: {causes}')

    def real_time_factor_scale(self, key: Hashable) -> float:
        """The ``real_time_factor_scale`` for the next try of episode ``key``: halved for each
        overloaded try since its last result with ``adaptive_rtf``; else 0 (unchanged)."""
        if not self.adaptive_rtf:
            return 0.0
        return real_time_factor_scale(sum(
            1 for cause, _ in self._failures.get(key, ()) if cause == Outcome.OVERLOADED))

    def succeeded(self, key: Hashable) -> None:
        """Forget the harness failures of episode ``key`` (it has a result now)."""
        self._failures.pop(key, None)
