"""Plain JSON data from what metrics, configs and episode facts hold (numpy, enums, paths)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np


def to_json_data(value: Any) -> Any:
    """``value`` as plain JSON data: numpy scalars and arrays to Python, enums to their value,
    paths to strings, tuples to lists, non-finite floats to None (JSON has no NaN).

    Raises TypeError for anything else.
    """
    if isinstance(value, Enum):
        return to_json_data(value.value)
    if isinstance(value, Mapping):
        return {str(k): to_json_data(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json_data(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_json_data(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f'{value!r:.80} ({type(value).__name__}) is not JSON data')
