"""Sensor presets (datasheet numbers) and the output stage shared by all sensors.

Sources (see docs/simulator.md):
- ADXRS623 gyro, HMC1022/1021 magnetoresistive compass, ADXL103/203 accelerometer: the sensor table of
  Feng, Li, Zhang, Sensors 2015, 15, 11222 (Table 1) and the Analog Devices / Honeywell datasheets.
- Xsens MTi-1 (+-2000 deg/s, 0.007 deg/s/sqrt(Hz)) as used by Kolesnyk & Chernyak (KPI 2023) on the
  carousel; where the MTi-1 sheet is silent, MTi-300 numbers of the same family (g-sensitivity).
White noise: per-sample std = density*sqrt(rate) (continuous-time density, Allan deviation at
tau = 1 s equals the density).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..constants import STANDARD_GRAVITY_M_S2


@dataclass(frozen=True)
class GyroSpec:
    noise_density_dps_rthz: float      # white rate noise (ARW), deg/s/sqrt(Hz)
    range_dps: float                   # output saturates at +-range
    lsb_dps: float                     # quantisation step of the digitised output
    # unit-to-unit ranges of the paper-model coefficients (drawn per axis, random sign)
    slope_dps_per_c: tuple[float, float]        # |a|
    rate_coeff_dps_per_c_per_s: tuple[float, float]  # |b|
    bias_at_25c_dps: float             # a*25 + c drawn in +-this


@dataclass(frozen=True)
class AccelSpec:
    noise_density_ug_rthz: float
    range_g: float
    lsb_g: float
    bias_mg: float                     # residual constant bias after calibration, drawn in +-this


@dataclass(frozen=True)
class MagSpec:
    noise_ut: float                    # per-sample rms noise of the whole compass chain, uT
    lsb_ut: float
    range_ut: float
    sensitivity_tc_per_c: float        # relative sensitivity change per degC, all axes alike


@dataclass(frozen=True)
class TempSensorSpec:
    lsb_c: float
    noise_c: float                     # rms, degC
    lag_s: float                       # the temperature sensor's own response time constant


@dataclass(frozen=True)
class ImuPreset:
    name: str
    gyro: GyroSpec
    accel: AccelSpec
    mag: MagSpec
    temp: TempSensorSpec

    def to_dict(self) -> dict:
        return asdict(self)


# ADXRS623: 12.5 mV/(deg/s) into a 16-bit ADC on 5 V -> 76 uV/LSB = 0.0061 deg/s. Thermal slope of
# MEMS gyro null: 0.005..0.08 deg/s/K across common parts; 23->58 degC must give a few tenths deg/s.
ADXRS623 = ImuPreset(
    name='adxrs623',
    gyro=GyroSpec(noise_density_dps_rthz=0.04, range_dps=150.0, lsb_dps=5.0 / 65536 / 0.0125,
                  slope_dps_per_c=(0.005, 0.015), rate_coeff_dps_per_c_per_s=(0.1, 0.4),
                  bias_at_25c_dps=0.3),
    # ADXL203: 110 ug/sqrt(Hz), +-1.7 g, 1000 mV/g into the same 16-bit ADC -> 76 ug/LSB.
    accel=AccelSpec(noise_density_ug_rthz=110.0, range_g=1.7, lsb_g=5.0 / 65536, bias_mg=5.0),
    # HMC1022: +-6 gauss, -0.3 %/degC sensitivity tempco (all axes); bridge noise (48 nV/sqrt(Hz)) is
    # far below the amplifier/ADC chain, taken as 0.1 uT rms per sample; 16 bits over +-600 uT.
    mag=MagSpec(noise_ut=0.1, lsb_ut=1200.0 / 65536, range_ut=600.0, sensitivity_tc_per_c=-0.003),
    # 12-bit digital temperature sensor (0.0625 degC/LSB) on the gyro board.
    temp=TempSensorSpec(lsb_c=0.0625, noise_c=0.02, lag_s=2.0),
)

# MTi-1: factory temperature-calibrated, so the residual thermal slope is small; turn-on biases of
# up to ~0.2 deg/s are implied by the static 300 s errors of Kolesnyk & Chernyak (Table 3).
MTI1 = ImuPreset(
    name='mti1',
    gyro=GyroSpec(noise_density_dps_rthz=0.007, range_dps=2000.0, lsb_dps=0.004,
                  slope_dps_per_c=(0.0005, 0.002), rate_coeff_dps_per_c_per_s=(0.02, 0.1),
                  bias_at_25c_dps=0.2),
    accel=AccelSpec(noise_density_ug_rthz=120.0, range_g=16.0, lsb_g=32.0 / 2 ** 20, bias_mg=1.0),
    mag=MagSpec(noise_ut=0.05, lsb_ut=0.002, range_ut=800.0, sensitivity_tc_per_c=-0.0005),
    temp=TempSensorSpec(lsb_c=1.0 / 256, noise_c=0.01, lag_s=2.0),
)

# LSM9DS1-class consumer 9-axis IMU: the carousel flip mechanism's auxiliary IMU (it only stands in for
# the ~0.5 s of a flip, so a cheap part will do). Full scale 2000 deg/s (70 mdps/LSB) so a 4 Hz table
# stays in range; zero-rate level and its tempco are large (sheet: up to +-30 dps at 2000 dps FS,
# +-0.05 dps/degC); +-1 deg/s drawn here since the offset is learnt against the main IMU anyway.
# Noise density: consumer MEMS order of magnitude (0.01-0.03 dps/sqrt(Hz)), not a verified sheet value.
LSM9DS1 = ImuPreset(
    name='lsm9ds1',
    gyro=GyroSpec(noise_density_dps_rthz=0.02, range_dps=2000.0, lsb_dps=0.07,
                  slope_dps_per_c=(0.005, 0.02), rate_coeff_dps_per_c_per_s=(0.05, 0.2),
                  bias_at_25c_dps=1.0),
    accel=AccelSpec(noise_density_ug_rthz=200.0, range_g=4.0, lsb_g=0.122e-3, bias_mg=60.0),
    mag=MagSpec(noise_ut=0.3, lsb_ut=0.014, range_ut=400.0, sensitivity_tc_per_c=-0.001),
    temp=TempSensorSpec(lsb_c=1.0 / 16, noise_c=0.05, lag_s=2.0),
)

PRESETS = {p.name: p for p in (ADXRS623, MTI1, LSM9DS1)}


def white_noise_std(density: float, rate_hz: float) -> float:
    """Per-sample std of white noise of continuous-time density `density` sampled at rate_hz."""
    return density * np.sqrt(rate_hz)


def digitise(x: np.ndarray, lsb: float, limit: float) -> np.ndarray:
    """Saturate at +-limit (the analog front end clips first), then quantise to the ADC step."""
    return lsb * np.round(np.clip(x, -limit, limit) / lsb)


def covariances(cfg):
    """Per-sample noise variances of a run's raw streams (white noise + quantisation, LSB^2/12), as the
    bag writer puts them into the sensor messages' covariance fields."""
    from ..bag_io import Covariances   # deferred: the simulator itself needs no bag I/O
    preset, p = cfg.preset, cfg.params
    gyro = (white_noise_std(p['gyro_noise_dps_rthz'], cfg.imu_rate_hz) ** 2
            + preset.gyro.lsb_dps ** 2 / 12) * np.radians(1.0) ** 2   # (deg/s)^2 -> (rad/s)^2
    accel = (white_noise_std(preset.accel.noise_density_ug_rthz * 1e-6, cfg.imu_rate_hz) ** 2
             + preset.accel.lsb_g ** 2 / 12) * STANDARD_GRAVITY_M_S2 ** 2
    mag = (preset.mag.noise_ut ** 2 + preset.mag.lsb_ut ** 2 / 12) * 1e-12
    temp = p['temp_noise_c'] ** 2 + preset.temp.lsb_c ** 2 / 12
    return Covariances(gyro_rad2_s2=[gyro] * 3, accel_m2_s4=[accel] * 3, mag_t2=[mag] * 3, temperature_c2=temp)
