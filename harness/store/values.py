"""What goes into a store's columns and comes out of them: canonical JSON, finite numbers, timestamps, rows.

A configuration's key hashes its parameters' canonical JSON (:func:`_dumps`: sorted keys,
integral floats as ints, so ``{"grid": 32.0}`` and ``{"grid": 32}`` are one key); a number
that goes into a column is finite or refused with the field's name (:func:`_finite`);
timestamps are UTC ISO 8601; a row read back is a dict that can also be indexed by
position (:class:`_Row`).
"""

import json
import math
from datetime import datetime, timezone
from pathlib import Path

from harness.errors import InputError


def _now():
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _plain(obj, canon=True):
    """JSON-ready copy: numpy scalars/arrays to Python, tuples to lists, integral floats to int.

    Integral floats become ints so that ``{"grid": 32.0}`` and ``{"grid": 32}``
    give the same configuration key.
    """
    if isinstance(obj, dict):
        return {str(k): _plain(v, canon) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v, canon) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):  # numpy scalar / array
        return _plain(obj.tolist(), canon)
    if isinstance(obj, Path):
        return str(obj)
    if canon and isinstance(obj, float) and math.isfinite(obj) and obj.is_integer() and abs(obj) < 2**53:
        return int(obj)
    return obj


def _dumps(obj, canon=True):
    """Compact sorted JSON; ``canon`` also turns integral floats into ints (for keys)."""
    return json.dumps(_plain(obj, canon), sort_keys=True, separators=(",", ":"), allow_nan=False)


def _loads(text):
    return None if text is None else json.loads(text)


def _finite(where, field, value, allow_none=False):
    """``value`` as a finite float, or an InputError naming the field."""
    if value is None and allow_none:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(where, field, f"is {value!r}, not a number", "record numbers only") from None
    if not math.isfinite(v):
        raise InputError(where, field, f"is {v}, not finite",
                         "record finite numbers (a failed config has status 'failed')")
    return v


class _Row(dict):
    """A result row: a dict that can also be indexed by position."""

    def __init__(self, names, values):
        super().__init__(zip(names, values))
        self._values = values

    def __getitem__(self, key):
        if isinstance(key, int):
            return self._values[key]
        return super().__getitem__(key)
