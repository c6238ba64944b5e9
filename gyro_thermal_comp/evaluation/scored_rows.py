"""One scored batch: IMU samples with their truth, as the heading scorer hands them on to the statistics,
the binned series, the reference window and the outage spans."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ScoredRows:
    """IMU samples with their truth: what one batch contributes to the scores (rad, rad/s)."""
    t: np.ndarray                       # (N,) s
    outage: np.ndarray                  # (N,) bool, inside a magnetic outage span
    true_drift: np.ndarray              # (N,) D_true (NaN without bias truth)
    error_raw: dict[str, np.ndarray]    # methods and ORACLE: continuous error before e0 is removed
    rate_error: dict[str, np.ndarray]   # methods, RAW and ORACLE: rate error for the Allan deviation
    drift: dict[str, np.ndarray]        # methods: drift estimate
    coasting: dict[str, np.ndarray]     # methods: bool, magnetic updates refused
    sigma: dict[str, np.ndarray] = field(default_factory=dict)   # methods: heading 1-sigma, rad
