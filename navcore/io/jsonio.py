"""Strict JSON for every document the project writes: no bare NaN / Infinity (RFC 8259 has none;
JavaScript's JSON.parse, jq and Go reject them). A non-finite number becomes null; a document that
has to say why a value is missing carries the reason beside it (e.g. the evaluation summary's
`null_means`). numpy scalars and arrays are written as plain numbers and lists.
"""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def strict(obj: Any) -> Any:
    """`obj` with every non-finite float as None, numpy scalars / arrays as Python numbers / lists,
    tuples as lists (dict keys kept; values recursed)."""
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return strict(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def dumps(obj: Any, **kwargs) -> str:
    """json.dumps of strict(obj) with allow_nan=False (a non-finite number left anywhere raises)."""
    return json.dumps(strict(obj), allow_nan=False, **kwargs)
