"""The command-line builder: one option per config field, with the shapes every command uses
(positional, choices, lists, old spellings) and validation as a usage error."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from sessgan_core.config_cli import build_parser, cli, parse_config, parse_valid_config
from sessgan_core.ros_spin import run_command

pytestmark = pytest.mark.unit


@dataclass
class Options:
    source: Path = field(metadata=cli(positional=True))
    """What to read."""
    names: tuple[str, ...] = ('a', 'b')
    """Names."""
    seeds: tuple[int, ...] = ()
    """Seeds."""
    record: Literal['all', 'none'] = 'all'
    """What to keep."""
    output_dir: Path | None = field(default=None, metadata=cli(old=['--output']))
    """Where it goes (default: beside the source)."""
    count: int = 3
    """How many."""

    def validate(self) -> None:
        if self.count < 1:
            raise ValueError(f'--count must be >= 1, got {self.count}')


def test_a_list_option_takes_commas_repeats_or_both_and_replaces_its_default():
    assert parse_config(Options, ['s']).names == ('a', 'b')
    assert parse_config(Options, ['s', '--names', 'x,y']).names == ('x', 'y')
    assert parse_config(Options, ['s', '--names', 'x', '--names', 'y']).names == ('x', 'y')
    assert parse_config(Options, ['s', '--seeds', '1,2', '--seeds', '3']).seeds == (1, 2, 3)
    with pytest.raises(SystemExit):
        parse_config(Options, ['s', '--seeds', 'one'])


def test_positional_choices_and_old_spellings():
    options = parse_config(Options, ['bag', '--record', 'none', '--output', 'here'])
    assert options.source == Path('bag') and options.record == 'none'
    assert options.output_dir == Path('here')
    assert parse_config(Options, ['bag', '--record', 'none', '--output-dir', 'here']) == options
    with pytest.raises(SystemExit):
        parse_config(Options, ['bag', '--record', 'some'])
    with pytest.raises(SystemExit):
        parse_config(Options, [])


def test_help_shows_defaults_once_and_hides_old_spellings():
    text = build_parser(Options).format_help()
    assert '--record {all,none}' in text and '(default: 3)' in text
    assert '--output ' not in text and 'OUTPUT ' not in text
    assert '(default: beside the source)' in text and '(default: None)' not in text
    assert 'comma-separated, the option repeated' in text


def test_a_value_validate_refuses_is_a_usage_error_with_status_2(capsys):
    assert parse_valid_config(Options, ['s', '--count', '2']).count == 2
    assert run_command(lambda: parse_valid_config(Options, ['s', '--count', '0']).count) == 2
    assert '--count must be >= 1, got 0' in capsys.readouterr().err
    assert run_command(lambda: parse_valid_config(Options, ['--help']).count) == 0
