"""Command lines from typed config dataclasses (CleanRL style: field docs become --help).

A field ``iterations: int = 0`` followed by a docstring becomes ``--iterations``
with that docstring as its help; bools become ``--name`` / ``--no-name``; a field that is
itself a config dataclass contributes its fields as ``--<field>-<name>``. Every command
(train, report, campaign) builds its options this way.
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


def add_config_arguments(parser: argparse.ArgumentParser, cls: type,
                         prefix: str = '') -> None:
    """Add one option per field of dataclass ``cls`` to ``parser``.

    A field that is itself a dataclass adds its fields with the prefix ``<field>_``
    (``fitness: FitnessConfig`` gives ``--fitness-tpkl-weight``, ...).
    """
    docs = field_docs(cls)
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        kind = hints[field.name]
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            add_config_arguments(parser, kind, f'{prefix}{field.name}_')
            continue
        name = prefix + field.name
        option = '--' + name.replace('_', '-')
        default = _default_of(field)
        help_text = docs.get(field.name, ' ').replace('%', '%%')  # argparse formats help
        if kind is bool:
            parser.add_argument(option, dest=name, default=default, help=help_text,
                                action=argparse.BooleanOptionalAction)
        else:
            parser.add_argument(option, dest=name, type=_base_type(kind), default=default,
                                help=help_text, metavar=field.name.upper())


def add_old_spelling(parser: argparse.ArgumentParser, old: str, dest: str,
                     **kwargs: Any) -> None:
    """Accept ``old``, the spelling of an option before it was renamed, for one release: it
    fills ``dest`` like the new one and is left out of --help."""
    parser.add_argument(old, dest=dest, help=argparse.SUPPRESS, default=argparse.SUPPRESS,
                        **kwargs)


def config_from_namespace(cls: type[ConfigT], namespace: argparse.Namespace,
                          prefix: str = '') -> ConfigT:
    """The ``cls`` instance of the options :func:`add_config_arguments` added."""
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = {}
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        kind = hints[field.name]
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            values[field.name] = config_from_namespace(kind, namespace, f'{prefix}{field.name}_')
        else:
            values[field.name] = getattr(namespace, prefix + field.name)
    return cls(**values)


def build_parser(
    cls: type, prog: str | None = None, description: str = ''
) -> argparse.ArgumentParser:
    """An argparse parser with one option per field of dataclass ``cls``."""
    parser = argparse.ArgumentParser(
        prog=prog, description=description,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_config_arguments(parser, cls)
    return parser


def parse_config(
    cls: type[ConfigT], argv: Sequence[str] | None, prog: str | None = None, description: str = ''
) -> ConfigT:
    """Parse ``argv`` (default: sys.argv[1:]) into an instance of dataclass ``cls``."""
    namespace = build_parser(cls, prog, description).parse_args(argv)
    return config_from_namespace(cls, namespace)


def _default_of(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f'config field {field.name!r} needs a default to become an option')


def _base_type(kind: Any) -> Any:
    """The converter for a field type: ``int | None`` -> int, ``str`` -> str."""
    args = [arg for arg in typing.get_args(kind) if arg is not type(None)]
    if args:
        return args[0]
    return kind
