"""One sensor unit's coefficients, drawn from the seed (unit-to-unit variation).

Every raw factor is drawn, in a fixed order, whatever the effect sizes: switching an effect on or off
or resizing it never changes the other coefficients of the same seed (the discovery workflow compares
runs that differ in one effect). Effect coefficients are VALUE times these factors (effects.py).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..constants import STANDARD_GRAVITY_M_S2
from .sensors import ImuPreset
from .thermal import T_REF_C

UNIT_STREAM = 1  # rng stream id of the unit draw (engine streams use others)
AUX_UNIT_STREAM = 24  # the auxiliary IMU's own unit (carousel flip mechanism)


def _axis_factors(rng) -> np.ndarray:
    """+-U(0.5, 1.5) on x, y; exactly +-1 on z (so |coefficient_z| = VALUE)."""
    size = rng.uniform(0.5, 1.5, 3)
    sign = rng.choice([-1.0, 1.0], 3)
    size[2] = 1.0
    return sign * size


def _row_factors(rng, off_diagonal: bool) -> np.ndarray:
    """3x3 factor matrix, each row a random direction scaled like _axis_factors (norm 1 on z)."""
    rows = rng.normal(size=(3, 3))
    if off_diagonal:
        np.fill_diagonal(rows, 0.0)
    rows /= np.linalg.norm(rows, axis=1, keepdims=True)
    return rows * np.abs(_axis_factors(rng))[:, None]


@dataclass(frozen=True)
class UnitCoefficients:
    """Per-axis (sensor x, y, z) coefficients in the units their names give."""
    gyro_a_dps_per_c: np.ndarray           # paper model D = a*T + b*dT/dt + c (T degC)
    gyro_b_dps_per_c_per_s: np.ndarray
    gyro_c_dps: np.ndarray
    gyro_curvature_dps_per_c2: np.ndarray  # thermal_curvature
    gyro_hysteresis_dps: np.ndarray        # thermal_hysteresis
    gyro_scale_factor: np.ndarray          # scale_factor, fraction
    gyro_scale_factor_tc_per_c: np.ndarray  # scale_factor_thermal, 1/degC
    gyro_cross_axis: np.ndarray            # 3x3, zero diagonal, fraction
    gyro_g_sensitivity_dps_per_g: np.ndarray  # 3x3
    gyro_rrw_dps_rts: np.ndarray           # rate_random_walk
    gyro_bias_instability_dps: np.ndarray  # bias_instability (Gauss-Markov sigma)
    accel_bias_m_s2: np.ndarray
    mag_hard_iron_ut: np.ndarray           # compass_deviation
    mag_soft_iron: np.ndarray              # 3x3, I + symmetric perturbation
    thermal_lag_s: float
    time_offset_s: float

    def to_dict(self) -> dict:
        return {f.name: np.asarray(getattr(self, f.name)).tolist() for f in fields(self)}


def draw_unit(seed: int, preset: ImuPreset, effects: dict[str, float],
              stream: int = UNIT_STREAM) -> UnitCoefficients:
    rng = np.random.default_rng([seed, stream])
    g = preset.gyro
    sign = rng.choice([-1.0, 1.0], (2, 3))
    a = sign[0] * rng.uniform(*g.slope_dps_per_c, 3)
    b = sign[1] * rng.uniform(*g.rate_coeff_dps_per_c_per_s, 3)
    bias25 = rng.uniform(-g.bias_at_25c_dps, g.bias_at_25c_dps, 3)
    f_curv, f_hyst, f_sf, f_sft, f_rrw, f_bi = (_axis_factors(rng) for _ in range(6))
    f_cross = _row_factors(rng, off_diagonal=True)
    f_gsens = _row_factors(rng, off_diagonal=False)
    accel_bias = rng.uniform(-1.0, 1.0, 3) * preset.accel.bias_mg * 1e-3 * STANDARD_GRAVITY_M_S2
    hard_dir = rng.normal(size=3)
    hard_dir /= np.linalg.norm(hard_dir)
    soft = rng.uniform(-0.25, 0.25, (3, 3))
    soft = 0.5 * (soft + soft.T)

    e = effects
    return UnitCoefficients(
        gyro_a_dps_per_c=a, gyro_b_dps_per_c_per_s=b, gyro_c_dps=bias25 - a * T_REF_C,
        gyro_curvature_dps_per_c2=e['thermal_curvature'] * f_curv,
        gyro_hysteresis_dps=e['thermal_hysteresis'] * f_hyst,
        gyro_scale_factor=e['scale_factor'] * f_sf,
        gyro_scale_factor_tc_per_c=e['scale_factor_thermal'] * f_sft,
        gyro_cross_axis=e['cross_axis'] * f_cross,
        gyro_g_sensitivity_dps_per_g=e['g_sensitivity'] * f_gsens,
        gyro_rrw_dps_rts=e['rate_random_walk'] * np.abs(f_rrw),
        gyro_bias_instability_dps=e['bias_instability'] * np.abs(f_bi),
        accel_bias_m_s2=accel_bias,
        mag_hard_iron_ut=e['compass_deviation'] * hard_dir,
        mag_soft_iron=np.eye(3) + (e['compass_deviation'] / 50.0) * soft,
        thermal_lag_s=float(e['thermal_lag']),
        time_offset_s=float(e['time_offset']),
    )
