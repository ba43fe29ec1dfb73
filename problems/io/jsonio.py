"""The one JSON encoding of femubench files: numpy values become plain Python, and non-finite
floats become the strings ``"inf"``, ``"-inf"`` and ``"nan"`` (strict JSON has no NaN), which
:func:`decode` turns back into floats.
"""

from __future__ import annotations

import json
import math
from typing import Any

_SPECIAL = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}


def plain(obj: Any) -> Any:
    """A copy of ``obj`` with numpy arrays and scalars as Python lists and numbers, dict keys as
    strings and tuples as lists (non-finite floats are kept: see :func:`encode`)."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):  # numpy arrays and scalars
        return plain(obj.tolist())
    return obj


def encode(obj: Any) -> Any:
    """A JSON-ready copy of ``obj``: dict keys as strings, numpy arrays and scalars as Python,
    non-finite floats as ``"inf"``, ``"-inf"``, ``"nan"``."""
    if isinstance(obj, dict):
        return {str(k): encode(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [encode(v) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):  # numpy arrays and scalars
        return encode(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


def decode(obj: Any) -> Any:
    """The inverse of :func:`encode` for the special strings (everything else is kept)."""
    if isinstance(obj, str) and obj in _SPECIAL:
        return _SPECIAL[obj]
    if isinstance(obj, dict):
        return {k: decode(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [decode(v) for v in obj]
    return obj


def dumps(obj: Any, **kw) -> str:
    """``json.dumps(encode(obj))`` in strict JSON (``allow_nan=False``)."""
    return json.dumps(encode(obj), allow_nan=False, **kw)


def loads(text: str) -> Any:
    """``decode(json.loads(text))``."""
    return decode(json.loads(text))
