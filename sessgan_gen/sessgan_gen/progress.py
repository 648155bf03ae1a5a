"""A small progress printer (tqdm is not a dependency): rate and ETA on stderr.

On a terminal it redraws one line; otherwise (logs, pipes) it prints a line at
most every ``log_interval`` seconds, so nohup logs stay readable.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


def format_duration(seconds: float) -> str:
    """'1:02:03' or '2:03' for a number of seconds; '?' when unknown."""
    if seconds != seconds or seconds < 0 or seconds == float('inf'):
        return '?'
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f'{hours}:{minutes:02d}:{secs:02d}' if hours else f'{minutes}:{secs:02d}'


class ProgressPrinter:
    """Prints '<label> [#####.....] 450/1000 12.3 it/s ETA 0:45 (elapsed 0:37)'."""

    def __init__(
        self,
        stream: TextIO | None = None,
        width: int = 24,
        redraw_interval: float = 0.2,
        log_interval: float = 10.0,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.interactive = bool(getattr(self.stream, 'isatty', lambda: False)())
        self.interval = redraw_interval if self.interactive else log_interval
        self.label = ''
        self.total = 0
        self.started = time.perf_counter()
        self.last_print = 0.0
        self.run_started = self.started

    def start(self, label: str, total: int) -> None:
        """Begin a new bar of ``total`` steps."""
        self.label, self.total = label, total
        self.started = time.perf_counter()
        self.last_print = self.started

    def update(self, done: int, extra: str = '') -> None:
        """Report ``done`` of ``total`` steps (prints when due and at the end)."""
        now = time.perf_counter()
        final = done >= self.total
        if not final and now - self.last_print < self.interval:
            return
        self.last_print = now
        elapsed = now - self.started
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else float('inf')
        filled = int(self.width * done / self.total) if self.total else self.width
        bar = '#' * filled + '.' * (self.width - filled)
        line = (f'{self.label} [{bar}] {done}/{self.total} {rate:.2f} it/s '
                f'ETA {format_duration(eta)} (elapsed {format_duration(elapsed)})')
        if extra:
            line += f' {extra}'
        if self.interactive:
            self.stream.write('\r' + line + ('\n' if final else ''))
        else:
            self.stream.write(line + '\n')
        self.stream.flush()
