"""JSON outputs. RFC 8259 JSON has no NaN or Infinity, and ``json.dumps(allow_nan=False)``
raises on them; a value that is not finite — an undefined χ²/ν of a fit with no degree of
freedom, say — is written as ``null`` (undefined), never as an invalid token or a crash."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def finite_or_null(obj: Any) -> Any:
    """``obj`` (nested dicts, lists, tuples, NumPy scalars and arrays) with every non-finite
    float replaced by None and NumPy values made plain Python."""
    if isinstance(obj, dict):
        return {k: finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_null(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite_or_null(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj: Any, **kwargs) -> str:
    """``json.dumps`` of :func:`finite_or_null` of ``obj`` (2-space indent unless given)."""
    kwargs.setdefault("indent", 2)
    return json.dumps(finite_or_null(obj), allow_nan=False, **kwargs)


__all__ = ["finite_or_null", "json_text"]
