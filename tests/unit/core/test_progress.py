"""Progress bars: tqdm on a terminal, whole tqdm lines at an interval in logs."""

from __future__ import annotations

import io

import pytest

from sessgan_core.progress import ProgressPrinter, format_duration

pytestmark = pytest.mark.unit


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_separate_lines_at_most_every_interval_and_the_last_one():
    log = io.StringIO()
    printer = ProgressPrinter(log, log_interval=3600.0)
    printer.start('generation 0/2', 3)
    printer.update(1, 'collisions so far 1')  # not due yet
    printer.update(3, 'collisions so far 4')  # the end is always shown
    lines = log.getvalue().splitlines()
    assert len(lines) == 1 and '\r' not in log.getvalue()
    assert lines[0].startswith('generation 0/2: 100%')
    assert '3/3' in lines[0] and 'collisions so far 4' in lines[0]


def test_a_terminal_gets_a_tqdm_bar():
    terminal = Terminal()
    printer = ProgressPrinter(terminal)
    printer.start('scale 1/3 8x8', 5)
    for done in range(1, 6):
        printer.update(done, 'total ETA 0:01')
    text = terminal.getvalue()
    assert '\r' in text and text.endswith('\n')
    assert 'scale 1/3 8x8: 100%' in text and '5/5' in text and 'total ETA 0:01' in text
    assert printer.bar is None  # closed at the end


def test_format_duration():
    assert format_duration(3723) == '1:02:03'
    assert format_duration(123.4) == '02:03'
    assert format_duration(float('nan')) == format_duration(float('inf')) == '?'
