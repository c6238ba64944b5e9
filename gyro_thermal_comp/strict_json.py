"""Plain data for strict JSON: reports are read by other tools, which reject NaN and numpy types."""
from __future__ import annotations

import math

import numpy as np


def json_safe(x):
    """NaN/inf -> None, numpy scalars and arrays -> Python, dict keys -> str; recursively."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
