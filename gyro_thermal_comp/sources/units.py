"""Units a recording may declare, per quantity, as (scale, offset) to the package's SI units:
rad/s, m/s^2, tesla, degC, seconds. Spelling is exact within a quantity (`mg` is milli-g for an
acceleration, `mG` milligauss for a field), with the common variants listed."""
from __future__ import annotations

import math

from .base import SourceError

_G0 = 9.80665
_UNITS: dict[str, dict[str, tuple[float, float]]] = {
    'angular_rate': {'rad/s': (1.0, 0.0), 'mrad/s': (1e-3, 0.0), 'deg/s': (math.pi / 180, 0.0),
                     'dps': (math.pi / 180, 0.0), 'rpm': (2 * math.pi / 60, 0.0)},
    'acceleration': {'m/s^2': (1.0, 0.0), 'm/s2': (1.0, 0.0), 'm s-2': (1.0, 0.0), 'm/s/s': (1.0, 0.0),
                     'g': (_G0, 0.0), 'mg': (_G0 * 1e-3, 0.0)},
    'magnetic_field': {'T': (1.0, 0.0), 'mT': (1e-3, 0.0), 'uT': (1e-6, 0.0), 'µT': (1e-6, 0.0),
                       'microT': (1e-6, 0.0), 'nT': (1e-9, 0.0), 'G': (1e-4, 0.0), 'gauss': (1e-4, 0.0),
                       'Ga': (1e-4, 0.0), 'mG': (1e-7, 0.0), 'mGauss': (1e-7, 0.0), 'milligauss': (1e-7, 0.0)},
    'temperature': {'degC': (1.0, 0.0), 'C': (1.0, 0.0), 'celsius': (1.0, 0.0), 'deg_C': (1.0, 0.0),
                    'K': (1.0, -273.15), 'degF': (5.0 / 9.0, -32.0 * 5.0 / 9.0), 'cdegC': (0.01, 0.0)},
    'time': {'s': (1.0, 0.0), 'ms': (1e-3, 0.0), 'us': (1e-6, 0.0), 'ns': (1e-9, 0.0)},
}
# the package's stream field -> its quantity
QUANTITY = {'gyro': 'angular_rate', 'accel': 'acceleration', 'mag': 'magnetic_field',
            'temperature': 'temperature', 'time': 'time'}


def _normal(unit: str) -> str:
    return ' '.join(str(unit).replace('²', '^2').replace('**', '^').split())


def lookup(quantity: str, unit: str) -> tuple[float, float] | None:
    """(scale, offset) of `unit` for `quantity`, or None if unknown."""
    table = _UNITS[quantity]
    text = _normal(unit)
    if text in table:
        return table[text]
    folded = [k for k in table if k.lower() == text.lower()]
    # case-folded only where it cannot mix up two units (mg/mG are different quantities' units)
    return table[folded[0]] if len(folded) == 1 else None


def conversion(field: str, unit: str) -> tuple[float, float]:
    """(scale, offset) converting `field` values in `unit` to SI; SourceError naming the known units."""
    quantity = QUANTITY[field]
    found = lookup(quantity, unit)
    if found is None:
        raise SourceError(f'{field}: unknown unit {unit!r} (known: {", ".join(_UNITS[quantity])})')
    return found


def same_unit(field: str, a: str, b: str) -> bool:
    """Do two spellings mean the same conversion? (False if either is unknown.)"""
    quantity = QUANTITY[field]
    ca, cb = lookup(quantity, a), lookup(quantity, b)
    return ca is not None and ca == cb
