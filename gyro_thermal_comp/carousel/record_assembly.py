"""Output record assembly: one `RevolutionRecord` per revolution or pass-through interval.

A revolution is demodulated only if it passes the validity checks (else it is reported as a
pass-through interval with the reason). Demodulated: the in-plane angle-domain mean over exactly one
turn (docs/design.md section 3), the spin rate from the revolution period. Pass-through: time means
of the per-sample body-frame values, with the last bias estimates removed.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .angle_reference import GravityAngleFilter
from .bias_book import SensorBiasBook
from .bias_learning import BiasLearner
from .blocks import (ANGLE_SOURCE_NAMES, GYRO, SOURCE_AUX, SOURCE_FLIP_WITHOUT_AUX, SOURCE_MAIN,
                     CoreBlock)
from .config import CarouselConfig
from .integrals import angle_integral
from .mag_reference import MagRevolution
from .records import DEMODULATED, PASS_THROUGH, Outbox, RevolutionRecord
from .revolutions import Crossing, rate_deviation
from .spin_coupling import SpinCoupling
from .temperature import TemperatureTrack
from .wheel_reference import WheelRevolution
from .window import IntervalWindow, cut_window


@dataclass(frozen=True)
class IntervalMeans:
    """Carousel-frame means over an output interval, bias estimates removed."""
    rate_rad_s: np.ndarray              # (3,), spin removed from z
    specific_force_m_s2: np.ndarray     # (3,)
    spin_rate_rad_s: float
    axial_residual_rad_s: float

    @classmethod
    def of(cls, *, gyro_inplane: complex, accel_inplane: complex, accel_axial: float, spin: float,
           axial: float) -> IntervalMeans:
        return cls(rate_rad_s=np.array([gyro_inplane.real, gyro_inplane.imag, axial], dtype=float),
                   specific_force_m_s2=np.array([accel_inplane.real, accel_inplane.imag, accel_axial], dtype=float),
                   spin_rate_rad_s=spin, axial_residual_rad_s=axial)


def _noise_variance(s) -> float:
    """Per-sample variance per in-plane component of the specific force about the revolution's two-point model
    z_p = b + exp(-i theta) w (a sensor-fixed bias, a body-fixed vector), by least squares, (m/s^2)^2: the noise
    its demodulated mean carries. The angle-domain mean cancels a constant bias exactly, so a bias the book does
    not know yet (the first revolutions) is no noise of it."""
    n = len(s.t)
    a = np.column_stack((np.ones(n), np.exp(-1j * s.theta)))
    x, *_ = np.linalg.lstsq(a, s.accel_inplane, rcond=None)
    return 0.5 * float(np.sum(np.abs(s.accel_inplane - a @ x) ** 2)) / max(n - 2, 1)


def _white_noise_density2(t: np.ndarray, rate: np.ndarray) -> float:
    """White-noise density^2 of a rate signal (rad^2/s) from its second differences, which leave a smooth
    signal (spin, its wobble, a wheel's acceleration) out: var = mean(d2^2) / 6 per sample, times the sample
    interval. 0 with too few samples."""
    if len(t) < 8:
        return 0.0
    d2 = np.diff(rate, 2)
    return float(np.mean(d2 ** 2) / 6.0 * (t[-1] - t[0]) / (len(t) - 1))


class RecordAssembler:
    """Turns the intervals the revolution core closes into records; clean revolutions also feed the
    bias learning. `mode` and `reason` are those of the newest record."""

    def __init__(self, config: CarouselConfig, book: SensorBiasBook, temperature: TemperatureTrack,
                 outbox: Outbox, counts: Counter, flip_position: Callable[[], int],
                 gravity: GravityAngleFilter, coupling: SpinCoupling):
        self.config = config
        self._book = book
        self._gravity = gravity          # learns the gyro angle's error from demodulated gravity
        self._coupling = coupling        # learns b0 + k * Omega of the in-plane gyro biases
        self._learner = BiasLearner(config, book)
        self._temperature = temperature
        self._outbox = outbox
        self._counts = counts
        self._flip_position = flip_position
        self._carousel_to_body = np.asarray(config.carousel_to_body, dtype=float).reshape(3, 3)
        self.mode, self.reason = PASS_THROUGH, 'no data yet'

    def report_pass_through(self, samples: CoreBlock, ta: float, tb: float, reason: str,
                            angle_source: int) -> None:
        window = cut_window(samples, self._book, ta, tb)
        if np.any(window.inside.source == SOURCE_FLIP_WITHOUT_AUX):
            reason = 'flip without auxiliary IMU; ' + reason
        s = window.signals
        turned = np.exp(1j * s.theta)        # no whole turn here: time means of carousel-frame samples
        gyro_p = self._at_rest(window, tb - ta)
        gyro_inplane = window.time_mean(turned * gyro_p)
        accel_inplane = window.time_mean(turned * s.accel_inplane)
        spin = float(window.time_mean(s.spin))
        axial = float(window.time_mean(s.gyro_axial)) - spin
        means = IntervalMeans.of(gyro_inplane=gyro_inplane, accel_inplane=accel_inplane,
                                 accel_axial=float(window.time_mean(s.accel_axial)), spin=spin, axial=axial)
        self._learner.calibrate_aux(window.inside, tb - ta)
        self._emit(window, means, PASS_THROUGH, reason, angle_source, self._temperature.over(ta, tb).mean_c)

    def report_revolution(self, samples: CoreBlock, start: Crossing, end: Crossing, angle_source: int) -> None:
        cfg = self.config
        ta, tb = start.t_s, end.t_s
        duration = tb - ta
        turn = end.level_rad - start.level_rad
        window = cut_window(samples, self._book, ta, tb, start.level_rad, end.level_rad)
        reason = self._rejection(window, duration)
        if reason:
            self._counts['revolutions_rejected'] += 1
            self.report_pass_through(samples, ta, tb, reason, angle_source)
            return
        self._counts['revolutions_demodulated'] += 1
        s = window.signals
        gyro_inplane, accel_inplane = angle_integral(s.theta, np.column_stack((s.gyro_inplane, s.accel_inplane))) / turn
        if angle_source == GYRO and cfg.nominal_spin_rate_rad_s is not None:
            spin = float(np.sign(turn) * abs(cfg.nominal_spin_rate_rad_s))
        else:
            spin = turn / duration      # the paper's spin estimate: one turn per revolution period
        axial = float(window.time_mean(s.gyro_axial)) - spin
        means = IntervalMeans.of(gyro_inplane=gyro_inplane, accel_inplane=accel_inplane,
                                 accel_axial=float(window.time_mean(s.accel_axial)), spin=spin, axial=axial)
        temperature = self._temperature.over(ta, tb)
        inside = window.inside
        if len(inside) and np.all(inside.source == SOURCE_MAIN) and np.all(inside.position == inside.position[0]):
            coupling = self._coupling_measurement(window) if not cfg.flip.enabled else None
            measured = self._learner.learn_revolution(inside, tb, duration, temperature)
            self._outbox.bias_measurements += measured
            if coupling is not None:
                self._coupling.add_revolution(tb, spin, *coupling, complex(gyro_inplane))
        if angle_source == GYRO and self._gravity.enabled:
            bias = self._book.main_platform(0).accel
            mag = MagRevolution.from_window(window, turn) if self._gravity.mag.enabled else None
            lag = self._gravity.observe_revolution(s.t, s.theta, complex(accel_inplane), _noise_variance(s),
                                                   complex(bias[0], bias[1]), mag,
                                                   self._wheel_revolution(window, gyro_inplane),
                                                   _white_noise_density2(inside.t, inside.gyro[:, 2]))
            turn_back = np.exp(-1j * lag)         # this revolution's angle error, as the filter now knows it
            means = IntervalMeans.of(gyro_inplane=gyro_inplane * turn_back, accel_inplane=accel_inplane * turn_back,
                                     accel_axial=means.specific_force_m_s2[2], spin=spin, axial=axial)
        self._learner.calibrate_aux(inside, duration)
        self._emit(window, means, DEMODULATED, '', angle_source, temperature.mean_c)

    def _wheel_revolution(self, window: IntervalWindow, gyro_inplane: complex) -> WheelRevolution | None:
        """On a wheel (wheel_radius_m): the revolution's end rates, in-plane gyro and axial specific force."""
        if self._gravity.wheel is None:
            return None
        s = window.signals
        return WheelRevolution(spin_a=float(s.gyro_axial[0]), spin_b=float(s.gyro_axial[-1]),
                               rate_inplane=complex(gyro_inplane), accel_axial=float(window.time_mean(s.accel_axial)))

    def _coupling_measurement(self, window: IntervalWindow) -> tuple[complex, float] | None:
        """The revolution's platform in-plane gyro bias at its time-mean spin rate (rad/s) and its variance
        per component, for the spin coupling. Least squares of the in-plane gyro on a bias, a bias slope
        with the spin rate (Omega(t) - its time mean: the k * Omega ramp of a spin-up or spin-down) and the
        body's constant rate turned into the platform frame. The lock-in's constant bias with a body trend
        takes up part of such a ramp (test_carousel_no_encoder), and the first revolutions after the still
        start, spinning up, are the ones that teach k. (No body trend: the coupling is learnt on a table,
        and the trend term costs 1.44x the variance.)"""
        s = window.signals
        n = len(s.t)
        if n < 8:
            return None
        d_spin = s.spin - window.time_mean(s.spin)
        columns = [np.ones(n), np.exp(-1j * s.theta)]
        if np.std(d_spin) > 1e-6:          # a steady rate: the slope is not observable (nor needed)
            columns.insert(1, d_spin / np.std(d_spin))
        a = np.column_stack(columns).astype(complex)
        x, *_ = np.linalg.lstsq(a, s.gyro_inplane, rcond=None)
        resid = s.gyro_inplane - a @ x
        var = 0.5 * float(np.sum(np.abs(resid) ** 2)) / max(n - a.shape[1], 1)     # per component
        g = np.linalg.inv((a.conj().T @ a))
        book = self._book.main_platform(0).gyro                 # the bias the window removed
        return (complex(x[0] + complex(book[0], book[1])),
                max(var * float(g[0, 0].real), self.config.bias_variance_floor))

    def _at_rest(self, window: IntervalWindow, duration: float) -> np.ndarray:
        """Platform in-plane gyro with the bias for this interval's spin rate removed: b0 + k * Omega once
        k is learnt (the lock-in bias holds k * Omega of the spin rate it was measured at), else the
        lock-in bias."""
        s, inside = window.signals, window.inside
        if self.config.flip.enabled or not len(inside) or np.any(inside.source != SOURCE_MAIN):
            return s.gyro_inplane
        omega = float((s.theta[-1] - s.theta[0]) / duration) if duration > 0 else 0.0
        stopped = abs(omega) < 2 * np.pi / self.config.max_revolution_period_s
        if not (self._coupling.for_rest() if stopped else self._coupling.known):
            return s.gyro_inplane
        book = self._book.main_platform(0).gyro
        return s.gyro_inplane + complex(book[0], book[1]) - self._coupling.bias_at(omega)

    def _rejection(self, window: IntervalWindow, duration: float) -> str:
        """Why a revolution cannot be demodulated ('' if it can)."""
        cfg = self.config
        n = len(window.inside)
        deviation = rate_deviation(window.signals.t, window.signals.theta)
        if n < cfg.min_samples_per_revolution:
            return f'revolution too short: {n} samples < {cfg.min_samples_per_revolution}'
        if duration > cfg.max_revolution_period_s:
            return f'rotation too slow: revolution took {duration:.2f} s > {cfg.max_revolution_period_s:g} s'
        if deviation > cfg.max_rate_deviation:
            return (f'rotation irregular: spin rate deviated {100 * deviation:.0f} % from the revolution mean '
                    f'(limit {100 * cfg.max_rate_deviation:.0f} %)')
        if np.any(window.inside.source == SOURCE_FLIP_WITHOUT_AUX):
            return 'flip without auxiliary IMU'
        return ''

    def _emit(self, window: IntervalWindow, means: IntervalMeans, mode: str, reason: str, angle_source: int,
              temperature_c: float | None) -> None:
        rate = self._carousel_to_body @ means.rate_rad_s
        specific_force = self._carousel_to_body @ means.specific_force_m_s2
        spin, axial = means.spin_rate_rad_s, means.axial_residual_rad_s
        if not (np.all(np.isfinite(rate)) and np.all(np.isfinite(specific_force)) and np.isfinite(spin)):
            # never propagate NaN: report the interval with zeros and say why
            self._counts['nonfinite_records'] += 1
            rate, specific_force, spin, axial = np.zeros(3), np.zeros(3), 0.0, 0.0
            mode, reason = PASS_THROUGH, 'numerical failure in interval (zeros reported)'
        in_use = self._book.main_platform(self._flip_position())
        drift = self._gravity.axial_bias if angle_source == GYRO else None
        axial_bias, axial_var = (0.0, np.inf) if drift is None else (drift[0], drift[1] ** 2)
        source, position = window.inside.source, window.inside.position
        ta, tb = window.signals.t[0], window.signals.t[-1]
        self._outbox.records.append(RevolutionRecord(
            t_s=float(tb), duration_s=float(tb - ta), rate_body_rad_s=rate, specific_force_body_m_s2=specific_force,
            spin_rate_rad_s=float(spin), axial_residual_rad_s=float(axial),
            gyro_bias_inplane_rad_s=in_use.gyro[:2].copy(), accel_bias_inplane_m_s2=in_use.accel[:2].copy(),
            gyro_bias_variance=float(self._learner.gyro_variance), mode=mode, reason=reason,
            angle_source=ANGLE_SOURCE_NAMES[angle_source], flip_position=int(position[-1]) if len(position) else 0,
            aux_fraction=float(np.mean(source == SOURCE_AUX)) if len(source) else 0.0, n_samples=len(source),
            temperature_c=temperature_c, axial_gyro_bias_rad_s=axial_bias, axial_gyro_bias_variance=axial_var))
        self.mode, self.reason = mode, reason
        self._counts['records_' + mode] += 1
