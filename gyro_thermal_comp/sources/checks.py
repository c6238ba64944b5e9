"""Is what a recording declares physically possible? Coarse bounds after conversion to SI, wide
enough for any uncalibrated MEMS unit at rest or in motion, narrow enough that a wrong unit (deg/s
read as rad/s, gauss as tesla, kelvin as degC, g as m/s^2) cannot pass. One SourceError line naming
the stream, its declared unit and what the data says."""
from __future__ import annotations

import numpy as np

from .base import SourceError

# field -> (SI unit, what it is at rest, low, high) for the median magnitude over the record
_BOUNDS = {
    'accel': ('m/s^2', 'about 9.8 m/s^2 at rest', 3.0, 30.0),
    'gyro': ('rad/s', 'a few deg/s of bias at rest', 0.0, 1.0),
    'mag': ('T', '25-65 uT of Earth field, a few hundred uT with hard iron', 1e-6, 2e-3),
    'temperature': ('degC', '-40..85 degC for an IMU', -60.0, 150.0),
}


def median_magnitude(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=float)
    v = np.linalg.norm(v, axis=1) if v.ndim == 2 else v
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else float('nan')


def check_magnitude(field: str, values: np.ndarray, declared: str, where: str) -> None:
    """SourceError if the median magnitude of `values` (SI) is outside the field's bounds."""
    unit, typical, lo, hi = _BOUNDS[field]
    m = median_magnitude(values)
    if not np.isfinite(m):
        return
    if not lo <= m <= hi:
        raise SourceError(f'{where}: {field} declared in {declared} reads a median {m:.4g} {unit} after conversion, '
                          f'expected {typical}: is its unit right?')


def check_streams(imu=None, mag=None, temperature=None, declared: dict | None = None, where: str = '') -> None:
    """Run `check_magnitude` on whatever is present; `declared` maps field -> the unit given."""
    declared = declared or {}
    if imu is not None and len(imu.t):
        check_magnitude('accel', imu.accel, declared.get('accel', 'm/s^2'), where)
        check_magnitude('gyro', imu.gyro, declared.get('gyro', 'rad/s'), where)
    if mag is not None and len(mag.t):
        check_magnitude('mag', mag.field, declared.get('mag', 'T'), where)
    if temperature is not None and len(temperature.t):
        check_magnitude('temperature', temperature.temp_c, declared.get('temperature', 'degC'), where)
