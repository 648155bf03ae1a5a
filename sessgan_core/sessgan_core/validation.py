"""Range checks of configuration values: the one place a number is found finite and positive
(or at least 0), so every config names what is wrong the same way: ``<name> must be > 0 m, got
nan``. NaN and infinity always fail (a NaN compares false with everything, so a bare
``value > 0`` would let it through)."""

from __future__ import annotations

import math
import numbers
import re
from typing import TypeGuard


def _shown(value: object) -> str:
    return str(value) if isinstance(value, numbers.Real) else repr(value)


def _finite_number(value: object) -> TypeGuard[float]:
    return isinstance(value, numbers.Real) and math.isfinite(value)


def require_positive(name: str, value: object, error: type[Exception] = ValueError,
                     unit: str = '') -> None:
    """Raise ``error`` naming ``name`` unless ``value`` is a finite number > 0 (``unit``, such
    as ``' m'``, goes into the message)."""
    if not (_finite_number(value) and value > 0):
        raise error(f'{name} must be > 0{unit}, got {_shown(value)}')


def require_non_negative(name: str, value: object, error: type[Exception] = ValueError,
                         unit: str = '') -> None:
    """Raise ``error`` naming ``name`` unless ``value`` is a finite number >= 0."""
    if not (_finite_number(value) and value >= 0):
        raise error(f'{name} must be >= 0{unit}, got {_shown(value)}')


_NAMESPACE = re.compile(r'/|/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*/?')


def ros_namespace(name: str, value: str, error: type[Exception] = ValueError) -> str:
    """``value`` as an absolute ROS namespace ('w0' and '/w0/' are '/w0', '/' the root);
    ``error`` naming ``name`` unless it is one (tokens of letters, digits and '_', not
    starting with a digit: no '..', no '//')."""
    if not _NAMESPACE.fullmatch(value):
        raise error(f'{name} must be a ROS namespace such as /w0, got {value!r}')
    return '/' + value.strip('/')
