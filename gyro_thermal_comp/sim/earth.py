"""The Earth as the sensors see it on a local ENU frame: rotation rate, gravity, geomagnetic field.

Transport rate (v / R_earth, about 2e-6 rad/s at 13 m/s) is neglected: it is 100x below the noise.
"""
from __future__ import annotations

import numpy as np

from ..constants import EARTH_RATE_RAD_S, STANDARD_GRAVITY_M_S2


def earth_rate_enu(latitude_rad: float) -> np.ndarray:
    """Earth rotation w.r.t. inertial space in ENU, rad/s: Omega*[0, cos(lat), sin(lat)]."""
    return EARTH_RATE_RAD_S * np.array([0.0, np.cos(latitude_rad), np.sin(latitude_rad)])


def specific_force_at_rest_enu() -> np.ndarray:
    """What an accelerometer at rest reads, in ENU, m/s^2 (it pushes up against gravity)."""
    return np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])


def geomagnetic_field_enu(total_t: float, dip_rad: float, declination_rad: float) -> np.ndarray:
    """Main field in ENU, T. Dip positive downward (northern hemisphere), declination east of north.

    Defaults used by the scenarios (50 uT, dip 66 deg, declination 7 deg) are IGRF-like values for
    central/eastern Europe at ~50 deg N.
    """
    horizontal = total_t * np.cos(dip_rad)
    return np.array([horizontal * np.sin(declination_rad),
                     horizontal * np.cos(declination_rad),
                     -total_t * np.sin(dip_rad)])
