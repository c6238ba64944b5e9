"""Carousel -> thermal drift model: learn D = a*T + b*dT/dt + c of the in-plane gyros without a compass.

Each clean revolution gives a `GyroBiasMeasurement` per in-plane imu axis: the drift over that
revolution, independent of the others. One fading-memory Kalman filter per axis (the STKF of
docs/design.md section 2: `thermal.stkf.StrongTrackingKF`, i.e. filterpy's KalmanFilter with
alpha = sqrt(s)) learns the `thermal.drift_model.DriftModel` parameters from them. When the carousel
stops, `drift()` predicts the drift of those axes from the live temperature alone (the filter coasts:
no measurements, parameters kept).

Spin coupling. A spinning carousel adds `k * Omega` to the in-plane biases it measures (sensor z
misaligned from the spin axis, gyro cross-axis sensitivity): sensor-fixed, so demodulation reports it
as bias, but it vanishes when the table stops. With one spin rate it is indistinguishable from c, so
the model carries the DriftModel 'rate' term with the spin rate as its input, and `add_still()` feeds
the raw mean of a motionless period (Omega = 0: the start-up still period every run has) to separate
them. The horizontal Earth rate seen in that period (<= 4.7e-5 rad/s at 50 deg N, unknown without a
compass) goes into c; drift() is the prediction at Omega = 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..thermal.drift_model import DriftModel
from ..thermal.stkf import StrongTrackingKF
from ..thermal.temperature_rate import TemperatureRateEstimator

LINK_TERMS = ('temperature', 'temperature_rate', 'constant', 'rate')


@dataclass(frozen=True)
class StillMeasurement:
    """The raw in-plane gyro mean of a motionless period (Earth rate included)."""
    bias_rad_s: dict                  # imu axis 'x' | 'y' -> rad/s
    variance_rad2_s2: float           # of each mean
    temperature_c: float
    temperature_rate_c_s: float = 0.0


@dataclass(frozen=True)
class ThermalLinkConfig:
    fading_s: float = 1.0005           # P <- s P + Q per measurement (~2000 revolutions of memory)
    temperature_ref_c: float = 25.0
    prior_sigma: tuple | None = None   # per term (SI); None: DriftModel defaults
    spin_coupling_sigma: float = 2e-3  # prior 1-sigma of k, rad/s per rad/s (cross-axis ~1e-3)
    reject_sigma: float = 6.0          # innovation gate of the STKF
    temperature_rate_window_s: float = 20.0  # live dT/dt for drift(): same window as the measurements


class CarouselThermalLink:
    """Per in-plane imu axis ('x', 'y'): STKF over the drift-model parameters fed by carousel bias
    measurements. `add(measurements, spin_rate_rad_s)` learns, `drift(T, dT/dt)` predicts (rad/s)."""

    def __init__(self, config: ThermalLinkConfig | None = None, axes=('x', 'y')):
        self.config = cfg = config or ThermalLinkConfig()
        self.model = DriftModel(LINK_TERMS, temperature_ref_c=cfg.temperature_ref_c)
        sig = self.model.prior_sigmas() if cfg.prior_sigma is None else np.asarray(cfg.prior_sigma, dtype=float)
        sig = sig.copy()
        sig[self.model.index('rate')] = cfg.spin_coupling_sigma
        q = self.model.q_sigmas().copy()
        q[self.model.index('rate')] = 0.0      # a mechanical misalignment does not wander
        self.axes = tuple(axes)
        # Q per step: q_sigma is per sqrt(s); one revolution (~2 s) per step is close enough for a prior
        self.filters = {ax: StrongTrackingKF(np.zeros(len(self.model)), np.diag(sig ** 2), np.diag(q ** 2),
                                             fading_s=cfg.fading_s, reject_sigma=cfg.reject_sigma)
                        for ax in self.axes}
        self.n_used = dict.fromkeys(self.axes, 0)
        self.t_last = None
        self._temp = TemperatureRateEstimator(window_s=cfg.temperature_rate_window_s)
        self._t_live = (np.nan, np.nan)

    def _h(self, temperature_c: float, temperature_rate_c_s: float, spin_rate_rad_s: float) -> np.ndarray:
        return self.model.rows({'temperature': np.array([temperature_c]),
                                'temperature_rate': np.array([temperature_rate_c_s]),
                                'rate': np.array([spin_rate_rad_s])})[0]

    def add(self, measurements, spin_rate_rad_s: float) -> int:
        """Learn from GyroBiasMeasurements (those of other axes or without temperature are skipped).
        spin_rate_rad_s: the table's rate during them (RevolutionRecord.spin_rate_rad_s, or
        2 pi / duration_s). Returns how many were accepted."""
        used = 0
        for m in measurements:
            if m.axis not in self.filters or m.temperature_c is None or m.temperature_rate_c_s is None:
                continue
            omega = float(spin_rate_rad_s) if np.isscalar(spin_rate_rad_s) else float(spin_rate_rad_s(m))
            res = self.filters[m.axis].step(m.bias_rad_s, self._h(m.temperature_c, m.temperature_rate_c_s, omega),
                                            m.variance_rad2_s2)
            used += res.accepted
            self.n_used[m.axis] += res.accepted
            self.t_last = m.t_s
        return used

    def add_still(self, still: StillMeasurement) -> None:
        """A motionless period's raw gyro mean (`still_measurement`): a measurement at spin rate 0."""
        h = self._h(still.temperature_c, still.temperature_rate_c_s, 0.0)
        for ax, y in still.bias_rad_s.items():
            if ax in self.filters:
                self.filters[ax].step(float(y), h, float(still.variance_rad2_s2))

    def update_temperature(self, t_s, temperature_c) -> None:
        """Live temperature samples (the carousel's temperature stream) for drift_now()."""
        est = self._temp.update(np.atleast_1d(t_s), np.atleast_1d(temperature_c))
        if len(est.t):
            self._t_live = (float(est.temp_c[-1]), float(est.rate_c_s[-1]))

    def drift(self, temperature_c, temperature_rate_c_s) -> np.ndarray:
        """Predicted drift of each axis (rad/s), shape (..., n_axes), at spin rate 0."""
        temp = np.atleast_1d(np.asarray(temperature_c, dtype=float))
        inputs = {'temperature': temp, 'temperature_rate': np.broadcast_to(temperature_rate_c_s, temp.shape),
                  'rate': np.zeros_like(temp)}
        rows = self.model.rows(inputs)
        return np.stack([rows @ self.filters[ax].x for ax in self.axes], axis=-1)

    def drift_now(self) -> np.ndarray:
        """Prediction from the latest live temperature (NaN before any temperature sample)."""
        return self.drift(*self._t_live)[0]

    def parameters(self) -> dict:
        return {ax: self.model.paper_coefficients(f.x) for ax, f in self.filters.items()}

    def sigmas(self) -> dict:
        return {ax: dict(zip(self.model.names, np.sqrt(np.diag(f.P)))) for ax, f in self.filters.items()}


def still_measurement(chunks, t_from: float, t_to: float, floor_rad_s: float = 3e-5) -> StillMeasurement:
    """A motionless period for `add_still`: the raw in-plane gyro mean over [t_from, t_to]. The variance is that of the mean from
    the scatter of 1 s block means, plus floor_rad_s^2 for the bias wander between this period and
    the carousel's revolutions (the Earth's horizontal rate, up to 4.7e-5 rad/s, is in the mean too)."""
    t = np.concatenate([c.imu.t for c in chunks if c.imu is not None])
    g = np.concatenate([c.imu.gyro for c in chunks if c.imu is not None])
    sel = (t >= t_from) & (t <= t_to)
    if np.count_nonzero(sel) < 10:
        raise ValueError(f'no still-period IMU samples in [{t_from}, {t_to}] s')
    ts, gs = t[sel], g[sel]
    blocks = np.floor(ts - ts[0]).astype(int)
    means = np.array([gs[blocks == b, :2].mean(axis=0) for b in np.unique(blocks)])
    var = float(np.mean(np.var(means, axis=0, ddof=1))) / max(len(means), 2) + floor_rad_s ** 2
    tt = np.concatenate([c.temperature.t for c in chunks if c.temperature is not None])
    tc = np.concatenate([c.temperature.temp_c for c in chunks if c.temperature is not None])
    tsel = (tt >= t_from) & (tt <= t_to)
    temp = float(np.mean(tc[tsel])) if np.any(tsel) else float(np.interp(0.5 * (t_from + t_to), tt, tc))
    mean = gs[:, :2].mean(axis=0)
    return StillMeasurement(bias_rad_s={'x': float(mean[0]), 'y': float(mean[1])}, variance_rad2_s2=var,
                            temperature_c=temp)
