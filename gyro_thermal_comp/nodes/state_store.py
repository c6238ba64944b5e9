"""Learned drift parameters on disk: atomic writes, forgiving reads (no ROS here).

A vehicle is switched off without warning; the file must never be half-written (write to a
temporary file in the same folder, fsync, rename). A missing, corrupt or foreign file means a cold
start with a warning, never a crash.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
import time
from pathlib import Path

FORMAT = 'gyro_thermal_comp/stkf_state/1'


def save_state(path, state: dict) -> None:
    """Atomically write the estimator state (`ThermalDriftEstimator.get_state()`) as JSON."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {'format': FORMAT, 'saved_unix_s': time.time(), **state}
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as f:
            json.dump(record, f, indent=1)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_state(path) -> tuple[dict | None, str]:
    """(state, message). state is None for a cold start (then message says why), else a warm start."""
    path = Path(path)
    if not path.exists():
        return None, f'no state file at {path}'
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        return None, f'state file {path} unreadable ({exc})'
    if not isinstance(record, dict) or record.get('format') != FORMAT:
        return None, f'state file {path} is not a {FORMAT} file'
    x = record.get('x')
    if not isinstance(x, list) or not x or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in x):
        return None, f'state file {path} has no finite parameters'
    P = record.get('P')
    if P is not None:
        ok = (isinstance(P, list) and len(P) == len(x)
              and all(isinstance(r, list) and len(r) == len(x) and all(isinstance(v, (int, float)) and math.isfinite(v)
                                                                       for v in r) for r in P))
        if not ok:
            return None, f'state file {path} has a malformed covariance'
    state = {k: v for k, v in record.items() if k not in ('format', 'saved_unix_s')}
    return state, f'warm start from {path}'
