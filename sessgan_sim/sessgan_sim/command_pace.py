"""Did the stack under test keep pace with sim time? (clocked mode; issue 21)

In clocked mode sim time advances at the real-time factor whatever the stack does. On a busy
machine a starved stack (or a simulator that catches up on lost ticks) sends its commands late
in sim time, and the robot drives on a stale command meanwhile: at load 14 on 2 cores the
reference navigator on its 20 Hz timer collided or got stuck on maps it passes when idle. That
is the harness's failure, not the controller's, so it must never become a fault.

The rule, in sim time, over the commands that arrived (at tick resolution: the sim time of the
tick whose wait took them; several in one tick are one arrival):

* the command period P is the declared one (``expected_command_period``), else the median of
  the first ``observed_gaps`` gaps between arrivals; never below the control period;
* a gap longer than ``gap_factor`` x P is *late*;
* the stack could not keep pace (``overloaded``) when late gaps cover more than ``late_share``
  of the measured sim time (the span from the first to the latest arrival), judged once that
  span is ``judged_after`` x P long and again at the episode's end, or at once when one gap
  exceeds ``long_gap_factor`` x P (the robot drove blind that long).

Silence is not lateness: the gap still open (no command since) is never counted, so a
controller that stops publishing at its goal is no overload and a silent one stays
``controller_unresponsive`` (wall-clock timeout). A gap the harness explains (a stack told its
navigation ended, a mission's next goal) is forgotten with :meth:`PaceMonitor.restart_gap`.
Nor is a pause: a gap after a stop command is not counted. Nav2 recovers with Wait (5 s in its
default behaviour tree): behavior_server stops the robot and nothing publishes cmd_vel until
the next behaviour. The robot stood as commanded meanwhile; it drove blind on nothing.
Lockstep needs none of this: the simulator waits for every answer.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import NamedTuple

from sessgan_sim.errors import InvalidConfigError

MIN_REAL_TIME_FACTOR_SCALE = 1.0 / 16.0
"""The slowest re-run an evaluate goal may ask for: its ``real_time_factor_scale`` floor
(four halvings: an episode of the scenario's time limit then takes 16 x its wall time)."""


def check_real_time_factor_scale(scale: float) -> float:
    """An evaluate goal's ``real_time_factor_scale`` as the factor to apply (0 means 1);
    ValueError naming it when outside [MIN_REAL_TIME_FACTOR_SCALE, 1]."""
    if scale == 0:
        return 1.0
    if not (math.isfinite(scale) and MIN_REAL_TIME_FACTOR_SCALE <= scale <= 1):
        raise ValueError(f"the goal's real_time_factor_scale must be 0 or in "
                         f'[{MIN_REAL_TIME_FACTOR_SCALE:g}, 1], got {scale}')
    return scale


@dataclass(frozen=True)
class PaceRule:
    """When a stack counts as unable to keep pace with sim time (units: sim seconds)."""

    expected_period: float = 0.0
    """The stack's command period; 0: observed (median of the first ``observed_gaps``)."""
    gap_factor: float = 3.0
    """A gap between commands longer than this many periods is late."""
    late_share: float = 0.1
    """Share of the measured sim time in late gaps above which the stack could not keep
    pace; 1 never judges an episode overloaded."""
    long_gap_factor: float = 40.0
    """One gap longer than this many periods is an overload on its own."""
    observed_gaps: int = 10
    """Gaps whose median is the period when none is declared."""
    judged_after: float = 200.0
    """Periods of measured sim time before the share is judged during the episode (it is
    judged at the end whatever the span): one late start-up gap (a stack planning its first
    route) must not end an episode two seconds in."""

    def validate(self) -> PaceRule:
        """InvalidConfigError naming the field that cannot work; self otherwise."""
        if not (math.isfinite(self.expected_period) and self.expected_period >= 0):
            raise InvalidConfigError(f'expected_command_period must be >= 0 sim s, got '
                                     f'{self.expected_period}')
        if not (math.isfinite(self.gap_factor) and self.gap_factor > 1):
            raise InvalidConfigError(f'overload_gap_factor must be > 1, got {self.gap_factor}')
        if not (math.isfinite(self.late_share) and 0 < self.late_share <= 1):
            raise InvalidConfigError(f'overload_late_share must be in (0, 1], got '
                                     f'{self.late_share}')
        if not (math.isfinite(self.long_gap_factor)
                and self.long_gap_factor >= self.gap_factor):
            raise InvalidConfigError(f'long_gap_factor ({self.long_gap_factor}) must be at '
                                     f'least gap_factor ({self.gap_factor})')
        if self.observed_gaps < 1 or not (math.isfinite(self.judged_after)
                                          and self.judged_after >= 0):
            raise InvalidConfigError('observed_gaps must be >= 1 and judged_after >= 0')
        return self


class PaceFigures(NamedTuple):
    """What the monitor measured so far (sim seconds)."""

    period: float | None
    """The command period in force (None while still being observed)."""
    declared: bool
    arrivals: int
    measured_time: float
    """Sim time spanned by closed gaps (first to latest arrival, less restarted gaps)."""
    late_gaps: int
    late_time: float
    longest_gap: float

    @property
    def late_share(self) -> float:
        return self.late_time / self.measured_time if self.measured_time > 0 else 0.0

    def summary(self) -> str:
        """One line for a log: the period, the late gaps and their share, the longest."""
        period = f'{self.period:.3f} s' if self.period else 'not measured yet'
        return (f'period {period}, {self.late_gaps} late gaps, {self.late_share:.1%} of '
                f'{self.measured_time:.1f} sim s late, longest gap {self.longest_gap:.2f} s')


class PaceMonitor:
    """Measures the arrivals of one robot's commands in one episode against a PaceRule."""

    def __init__(self, rule: PaceRule, control_period: float) -> None:
        """``control_period``: the simulator's tick (sim s), the finest gap it can see."""
        self.rule = rule.validate()
        self.control_period = control_period
        self._declared = rule.expected_period > 0
        self._period: float | None = (max(rule.expected_period, control_period)
                                      if self._declared else None)
        self._last: float | None = None
        self._paused = False
        """Whether the last arrival was a stop: the gap after it is a pause, not late."""
        self._gaps: list[float] = []
        self._judged = 0  # gaps already classified against the period
        self._arrivals = 0
        self._measured = 0.0
        self._late_gaps = 0
        self._late_time = 0.0
        self._longest = 0.0

    def command(self, sim_time: float, stop: bool = False) -> None:
        """Commands arrived in the tick at ``sim_time`` (episode sim s; non-decreasing), the
        latest a stop or not (the gap until the next arrival is then a pause)."""
        if self._last is not None and sim_time <= self._last:
            self._paused = stop
            return  # the same tick: one arrival
        self._arrivals += 1
        if self._last is not None and not self._paused:
            self._gaps.append(sim_time - self._last)
        self._last, self._paused = sim_time, stop
        if self._period is None and len(self._gaps) >= self.rule.observed_gaps:
            observed = statistics.median(self._gaps[:self.rule.observed_gaps])
            self._period = max(observed, self.control_period)
        if self._period is not None:
            late_after = self.rule.gap_factor * self._period
            for gap in self._gaps[self._judged:]:
                self._measured += gap
                self._longest = max(self._longest, gap)
                if gap > late_after + 1e-9:
                    self._late_gaps += 1
                    self._late_time += gap
            self._judged = len(self._gaps)

    def restart_gap(self) -> None:
        """Forget the last arrival: the gap until the next one is explained (the stack was
        told to stop, or got a new goal), not late."""
        self._last = None

    @property
    def paused(self) -> bool:
        """Whether the latest command was a stop (the gap after it is a pause)."""
        return self._paused

    def silent_for(self, sim_time: float) -> float | None:
        """Sim seconds from the last arrival to ``sim_time`` (the gap still open); None
        before the first arrival or after an explained gap (:meth:`restart_gap`)."""
        return None if self._last is None else sim_time - self._last

    @property
    def figures(self) -> PaceFigures:
        return PaceFigures(self._period, self._declared, self._arrivals, self._measured,
                           self._late_gaps, self._late_time, self._longest)

    def overload(self, final: bool = False) -> str | None:
        """None while the stack keeps pace, else the detail of an ``overloaded`` episode
        (the figures). ``final``: the episode ended, judge the share whatever the span."""
        figures = self.figures
        period = figures.period
        if period is None:
            return None
        rule = self.rule
        if figures.longest_gap > rule.long_gap_factor * period + 1e-9:
            return self.describe(f'a gap of {figures.longest_gap:.2f} sim s between commands '
                                 f'(over {rule.long_gap_factor:g} periods)')
        judged = final or figures.measured_time >= rule.judged_after * period
        if judged and figures.late_share > rule.late_share:
            return self.describe(f'{figures.late_share:.0%} of the time in late gaps (more '
                                 f'than {rule.late_share:.0%})')
        return None

    def describe(self, reason: str) -> str:
        """The detail of an overloaded episode: the reason and every figure."""
        figures = self.figures
        period = figures.period or 0.0
        source = 'declared' if figures.declared else 'observed'
        return (f'the stack could not keep pace with sim time: {reason}; '
                f'{figures.late_gaps} gap(s) over {self.rule.gap_factor:g} x the {source} '
                f'command period of {period:.3f} s took {figures.late_time:.2f} of '
                f'{figures.measured_time:.2f} sim s, longest {figures.longest_gap:.2f} s, '
                f'{figures.arrivals} command ticks')
