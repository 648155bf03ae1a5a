"""Progress bars on stderr (tqdm): count, rate, ETA and a free-text status.

On a terminal tqdm redraws one line. In a log or a pipe tqdm's carriage returns would pile up
into one endless line, so there the same tqdm meter is printed as a line of its own at most
every ``log_interval`` seconds (and at the end): nohup logs stay readable.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from tqdm import tqdm


def format_duration(seconds: float) -> str:
    """'1:02:03' or '02:03' for a number of seconds (tqdm's format); '?' when unknown."""
    if seconds != seconds or seconds < 0 or seconds == float('inf'):
        return '?'
    return tqdm.format_interval(int(round(seconds)))


class ProgressPrinter:
    """One bar at a time: ``start(label, total)``, then ``update(done, extra)``."""

    def __init__(
        self,
        stream: TextIO | None = None,
        redraw_interval: float = 0.2,
        log_interval: float = 10.0,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.interactive = bool(getattr(self.stream, 'isatty', lambda: False)())
        self.redraw_interval = redraw_interval
        self.log_interval = log_interval
        self.bar: tqdm | None = None
        self.label = ''
        self.total = 0
        self.started = time.perf_counter()
        self.last_print = 0.0

    def start(self, label: str, total: int) -> None:
        """Begin a new bar of ``total`` steps (ending the previous one)."""
        self.close()
        self.label, self.total = label, total
        self.started = time.perf_counter()
        self.last_print = self.started
        if self.interactive:
            self.bar = tqdm(total=total, desc=label, file=self.stream, leave=True,
                            mininterval=self.redraw_interval, dynamic_ncols=True)

    def update(self, done: int, extra: str = '') -> None:
        """Report ``done`` of ``total`` steps (shown when due and at the end)."""
        final = done >= self.total
        if self.bar is not None:
            self.bar.set_postfix_str(extra, refresh=False)
            self.bar.update(done - self.bar.n)
            if final:
                self.close()
            return
        now = time.perf_counter()
        if not final and now - self.last_print < self.log_interval:
            return
        self.last_print = now
        line = tqdm.format_meter(done, self.total, now - self.started, prefix=self.label,
                                 postfix=extra or None, ncols=100)
        self.stream.write(line + '\n')
        self.stream.flush()

    def note(self, line: str) -> None:
        """Print ``line`` above the bar (it redraws below)."""
        if self.bar is not None:
            self.bar.write(line, file=self.stream)
        else:
            self.stream.write(line + '\n')
            self.stream.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
