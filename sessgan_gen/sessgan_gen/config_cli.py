"""Command lines from typed config dataclasses (CleanRL style: field docs become --help).

A field ``iterations: int = 0`` followed by a docstring becomes ``--iterations``
with that docstring as its help; bools become ``--name`` / ``--no-name``.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import textwrap
import typing
from collections.abc import Sequence
from typing import Any, TypeVar

ConfigT = TypeVar('ConfigT')


def field_docs(cls: type) -> dict[str, str]:
    """Map each field of dataclass ``cls`` to the docstring written under it (if any)."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):  # no source (frozen install): no help texts
        return {}
    docs: dict[str, str] = {}
    body = ast.parse(source).body[0]
    if not isinstance(body, ast.ClassDef):
        return docs
    statements = body.body
    for statement, following in zip(statements, statements[1:], strict=False):
        if (isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)):
            docs[statement.target.id] = ' '.join(following.value.value.split())
    return docs


def build_parser(
    cls: type, prog: str | None = None, description: str = ''
) -> argparse.ArgumentParser:
    """An argparse parser with one option per field of dataclass ``cls``."""
    parser = argparse.ArgumentParser(
        prog=prog, description=description,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    docs = field_docs(cls)
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        option = '--' + field.name.replace('_', '-')
        kind = hints[field.name]
        default = field.default
        help_text = docs.get(field.name, ' ').replace('%', '%%')  # argparse formats help
        if kind is bool:
            parser.add_argument(option, default=default, help=help_text,
                                action=argparse.BooleanOptionalAction)
        else:
            base = _base_type(kind)
            parser.add_argument(option, type=base, default=default, help=help_text,
                                metavar=field.name.upper())
    return parser


def parse_config(
    cls: type[ConfigT], argv: Sequence[str] | None, prog: str | None = None, description: str = ''
) -> ConfigT:
    """Parse ``argv`` (default: sys.argv[1:]) into an instance of dataclass ``cls``."""
    namespace = build_parser(cls, prog, description).parse_args(argv)
    return cls(**vars(namespace))


def _base_type(kind: Any) -> Any:
    """The converter for a field type: ``int | None`` -> int, ``str`` -> str."""
    args = [arg for arg in typing.get_args(kind) if arg is not type(None)]
    if args:
        return args[0]
    return kind
