"""Command lines from typed config dataclasses (CleanRL style: field docs become --help).

A field ``iterations: int = 0`` followed by a docstring becomes ``--iterations``
with that docstring as its help; bools become ``--name`` / ``--no-name``; a ``Literal`` field
takes one of its values; a ``tuple[X, ...]`` field takes several values, comma-separated, the
option repeated, or both; a field that is itself a config dataclass contributes its fields as
``--<field>-<name>``. :func:`cli` marks a field positional or gives the old spellings it still
accepts. Every command builds its options this way, so help, defaults, validation (the
config's ``validate``: :func:`parse_valid_config`) and the usage-error status 2 come from here.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import textwrap
import typing
from collections.abc import Callable, Sequence
from typing import Any, Literal, TypeVar

ConfigT = TypeVar('ConfigT')


def cli(*, old: Sequence[str] = (), positional: bool = False) -> dict[str, Any]:
    """A config field's ``metadata`` for its option: ``old`` spellings it still accepts
    (hidden from --help, :func:`add_old_spelling`), or a ``positional`` argument."""
    return {'old_spellings': tuple(old), 'positional': positional}


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The description as written; each option's default after its help, unless the help
    says the default itself."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ''
        if ('default' in text.lower() or action.default is argparse.SUPPRESS
                or not action.option_strings or action.default in (None, '', ())):
            return text
        return text + ' (default: %(default)s)'


class _ListOption(argparse.Action):
    """Several values: comma-separated, the option repeated, or both; the first use replaces
    the default."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        current = getattr(namespace, self.dest, None)
        if current is self.default or current is None:
            current = ()
        setattr(namespace, self.dest, (*current, *values))


def field_docs(cls: type) -> dict[str, str]:
    """Map each field of dataclass ``cls`` to the docstring written under it (if any)."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):  # no source (frozen install): no help texts
        return {}
    docs: dict[str, str] = {}
    for base in reversed(cls.__mro__[1:]):  # the fields a config inherits keep their help
        if dataclasses.is_dataclass(base):
            docs.update(field_docs(base))
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
        help_text = docs.get(field.name, ' ').replace('%', '%%')  # argparse formats help
        if field.metadata.get('positional'):
            parser.add_argument(name, type=_base_type(kind), help=help_text,
                                metavar=field.name.upper())
            continue
        option = '--' + name.replace('_', '-')
        settings = _option_settings(kind, field.name)
        if settings.get('action') is _ListOption:
            help_text += ' Several: comma-separated, the option repeated, or both.'
        parser.add_argument(option, dest=name, default=_default_of(field), help=help_text,
                            **settings)
        for old in field.metadata.get('old_spellings', ()):
            add_old_spelling(parser, old, name, **settings)


def _option_settings(kind: Any, name: str) -> dict[str, Any]:
    """argparse's settings (action, type, choices, metavar) of an option of type ``kind``."""
    if kind is bool:
        return {'action': argparse.BooleanOptionalAction}
    if typing.get_origin(kind) is Literal:
        return {'choices': typing.get_args(kind)}
    if typing.get_origin(kind) is tuple:
        if typing.get_args(kind)[1:] != (Ellipsis,):
            raise TypeError(f'config field {name!r}: a list option is a tuple[X, ...]')
        item = _base_type(typing.get_args(kind)[0])

        def items(text: str) -> tuple[Any, ...]:
            return tuple(item(part.strip()) for part in text.split(',') if part.strip())
        items.__name__ = getattr(item, '__name__', 'value')  # argparse names it in errors
        return {'action': _ListOption, 'type': items, 'metavar': name.upper()}
    return {'type': _base_type(kind), 'metavar': name.upper()}


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
    parser = argparse.ArgumentParser(prog=prog, description=description,
                                     formatter_class=HelpFormatter)
    add_config_arguments(parser, cls)
    return parser


def parse_config(
    cls: type[ConfigT], argv: Sequence[str] | None, prog: str | None = None, description: str = ''
) -> ConfigT:
    """Parse ``argv`` (default: sys.argv[1:]) into an instance of dataclass ``cls``."""
    namespace = build_parser(cls, prog, description).parse_args(argv)
    return config_from_namespace(cls, namespace)


def parse_valid_config(
    cls: type[ConfigT], argv: Sequence[str] | None, prog: str | None = None,
    description: str = '', errors: tuple[type[Exception], ...] = (ValueError,)
) -> ConfigT:
    """:func:`parse_config`, then the config's ``validate()``: a value it refuses with one of
    ``errors`` is a usage error (the message, exit status 2), like a value argparse refuses."""
    parser = build_parser(cls, prog, description)
    config = config_from_namespace(cls, parser.parse_args(argv))
    validate: Callable[[], Any] = getattr(config, 'validate')
    try:
        validate()
    except errors as err:
        parser.error(str(err))
    return config


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
