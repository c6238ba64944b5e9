"""Learning the bias book: lock-in estimates from clean revolutions, the aux offset from every interval.

Each clean revolution also yields an independent single-revolution `GyroBiasMeasurement` per
in-plane imu axis, for a thermal drift estimator (docs/carousel.md, "Link to the thermal drift
estimator").
"""
from __future__ import annotations

import numpy as np

from .bias_book import SensorBiasBook
from .blocks import SOURCE_MAIN, CoreBlock
from .config import CarouselConfig
from .flip import platform_axis_to_imu
from .integrals import inplane
from .lockin import LockInEstimator, RevolutionStats, solve
from .records import GyroBiasMeasurement
from .temperature import IntervalTemperature


class BiasLearner:
    """Updates the shared `SensorBiasBook`; `gyro_variance` is that of the in-plane estimate in use."""

    def __init__(self, config: CarouselConfig, book: SensorBiasBook):
        self.config = config
        self.book = book
        self._lockin = LockInEstimator(config.lockin_revolutions, config.lockin_poly_order,
                                       config.lockin_max_span_s, config.bias_variance_floor)
        self.gyro_variance = np.inf      # of the lock-in estimate in use, (rad/s)^2 per component

    def learn_revolution(self, inside: CoreBlock, tb: float, duration_s: float,
                         temperature: IntervalTemperature) -> list[GyroBiasMeasurement]:
        """Add one clean revolution (main IMU only, one position) ending at tb; its own measurements."""
        cfg = self.config
        k = int(inside.position[-1])
        t_ref = float(tb - 0.5 * duration_s)
        # Gyro and accelerometer share t and theta, hence one set of normal equations.
        stats = RevolutionStats.from_samples(inside.t, inside.theta,
                                             np.column_stack((inplane(inside.gyro), inplane(inside.accel))),
                                             max(cfg.lockin_poly_order, cfg.measurement_poly_order), t_ref)
        measurements = []
        single = solve([stats], cfg.measurement_poly_order, t_ref, cfg.bias_variance_floor)
        if single is not None:
            gyro = single[0]
            for p_axis, value in ((0, gyro.bias.real), (1, gyro.bias.imag)):
                j, sign = platform_axis_to_imu(cfg.flip.axis, k, p_axis)
                measurements.append(GyroBiasMeasurement(
                    t_s=float(tb), duration_s=float(duration_s), axis='xyz'[j], bias_rad_s=float(sign * value),
                    variance_rad2_s2=float(gyro.bias_variance), temperature_c=temperature.mean_c,
                    temperature_rate_c_s=temperature.rate_c_s, flip_position=k))
        self._lockin.add(stats, tag=k)
        window = self._lockin.estimate(tb)
        if window is not None:
            gyro, accel = window
            self.book.update_inplane(k, gyro.bias, accel.bias, gyro.bias_variance, accel.bias_variance, tb)
            self.gyro_variance = gyro.bias_variance
        return measurements

    def calibrate_aux(self, inside: CoreBlock, duration_s: float) -> None:
        """Blend this interval's mean (aux - main) platform-frame difference into the book."""
        if not self.config.flip.enabled:
            return
        both = inside.aux_ok & (inside.source == SOURCE_MAIN)
        k = inside.position
        if np.count_nonzero(both) < 2 or np.any(k[both] != k[both][0]):
            return
        gyro_diff = np.mean(inside.aux_gyro[both] - inside.gyro[both], axis=0)
        accel_diff = np.mean(inside.aux_accel[both] - inside.accel[both], axis=0)
        weight = 1.0 - np.exp(-duration_s / self.config.flip.aux_calibration_tau_s)
        self.book.update_aux(int(k[both][0]), gyro_diff, accel_diff, weight)
