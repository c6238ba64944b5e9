"""`ThermalDriftEstimator`: the STKF thermal-drift heading method (design section 2), streaming.

Pipeline per chunk (any size: one 1 kHz sample from a live node, or an hour of a bag):
  1. inputs cleaned: samples with NaN/inf are dropped and counted; stamps not after the previous one
     (repeated / out of order) are dropped and counted; every IMU row still gets an output row
     (holding the last good values, reason `dropped_input`);
  2. temperature -> local-regression T and dT/dt (temperature_rate.py), looked up causally at the
     IMU stamps;
  3. between filter events (window ends, confirmations: every few seconds) everything is vectorised:
     D_hat = H x (drift_model.py), compensated rates, heading rate from the tilt, integrated gyro
     heading psi_g; compass heading/norm/dip per magnetometer sample (compass.py);
  4. compass samples are grouped in short blocks (`compass_block_s`); per block the magnetic gate
     (magnetic_gate.py) decides open/closed and the heading filter (heading_filter.py) corrects
     the output heading while open. Block results take effect at the block end (a causal delay of
     at most one block);
  5. every `window_s` the drift measurement of the window (stkf.DriftWindow, exact form of eq. 4-6)
     is formed; if the gate stayed open over the window and `confirm_s` after it (an interference
     that begins slowly is caught before its window is used), the STKF steps with it; otherwise it
     only fades (predicts). While the gate is shut the estimator COASTS: D_hat = H x with the last
     parameters and the live temperature.

Time gaps (IMU stamps further apart than `max_gap_s`): nothing is integrated across the gap (the
rate during it is unknown), the heading uncertainty is inflated by `gap_rate_sigma_rad_s` x gap, the
drift window containing it is discarded, the compass-mismatch history is reset, and the sample is
flagged `time_gap`. The learned parameters survive everything: they only change through accepted
STKF updates (stkf.py refuses non-finite or wildly inconsistent ones).

A unit is assumed motionless for the first `still_period_s` (shortened if the gyro heading moves by
`still_motion_deg`): its mean rates give the initial biases (c0 = mean(w) - a0 (T0 - t_ref)), its
field the gate references, its compass scatter the compass noise.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..angles import wrap_angle
from ..constants import EARTH_RATE_RAD_S, STANDARD_GRAVITY_M_S2
from ..heading_track import HeadingTrack
from ..samples import SensorChunk
from .compass import compass_heading, roll_pitch_from_accel
from .drift_model import CURVATURE_TERMS, SCALE_FACTOR_TERMS, DriftModel
from .heading_filter import HeadingFilter, HeadingFilterConfig
from .magnetic_gate import BIT, REASONS as GATE_REASONS, GateConfig, MagneticGate
from .stkf import DriftWindow, StrongTrackingKF
from .temperature_rate import TemperatureEstimate, TemperatureRateEstimator

# Reason bits of the per-sample output: the gate's, then the estimator's own.
EXTRA_REASONS = ('heading_innovation', 'no_compass', 'time_gap', 'temperature_stuck', 'still_period',
                 'dropped_input')
REASONS = GATE_REASONS + EXTRA_REASONS
REASON_BIT = {**BIT, **{name: 1 << (len(GATE_REASONS) + i) for i, name in enumerate(EXTRA_REASONS)}}


@dataclass(frozen=True)
class EstimatorConfig:
    """Defaults suit an ADXRS623-class gyro (0.04 deg/s/sqrt(Hz)) at 100 Hz-1 kHz with a compass."""
    name: str = 'stkf'                        # method name in reports
    # drift model
    terms: tuple[str, ...] = CURVATURE_TERMS  # PAPER_TERMS for the paper's a, b, c exactly
    scale_factor: bool = False                # add k(T) = k1 (T - t_ref) + k0 terms (needs rotation)
    temperature_ref_c: float = 25.0           # temperature terms use T - this, degC
    # parameter learning (STKF)
    learn: bool = True                        # False: parameters fixed (baselines, replay of a calibration)
    window_s: float = 10.0                    # update interval and drift-measurement window
    edge_s: float = 1.0                       # compass averaging at each window end (0 = paper's points)
    confirm_s: float = 5.0                    # gate must stay open this long after a window
    fading_s: float = 1.002                   # s per window (design eq. 10); 1 = plain KF
    adaptive_fading: bool = False             # Zhou's lambda_k >= 1 on top of s
    prior_sigmas: tuple[float, ...] | None = None  # per term, SI; None = the terms' defaults
    q_sigmas: tuple[float, ...] | None = None      # per term random walk per sqrt(s); None = defaults
    r_floor_rad_s: float = 2e-5               # model-error floor added to each window's noise, rad/s
    reject_sigma: float = 6.0                 # a window innovation beyond this many sigma is refused
    innovation_windows: int = 30              # windows behind the empirical drift uncertainty
    # sensors
    arw_deg_sqrt_s: float = 0.04              # gyro angle random walk = noise density, deg/s/sqrt(Hz)
    latitude_deg: float | None = None         # subtract Earth rate if known (else it ends up in c)
    temp_window_s: float = 60.0               # local-regression window for T and dT/dt, s
    temp_stuck_s: float = 600.0               # a reading unchanged this long is flagged stuck, s
    temp_hold_max_s: float = 5.0              # extrapolate the temperature line at most this long, s
    declination_rad: float = 0.0              # magnetic declination, east positive, rad
    compass_block_s: float = 0.1              # compass samples are averaged in blocks this long, s
    compass_sigma_deg: float | None = None    # None: learned over the still period
    compass_sigma_floor_deg: float = 0.05     # lower bound of the learned compass noise, deg
    compass_sigma_default_deg: float = 0.5    # used until learned
    mag_timeout_s: float = 1.0                # no compass sample for this long: coasting, s
    tilt_window_s: float = 120.0              # accelerometer averaging for roll/pitch: long, so a
                                              # car's acceleration and braking average out (turning
                                              # samples, with centripetal force, are left out)
    # start, gaps
    still_period_s: float = 30.0              # motionless at start for this long (initial bias), s
    still_motion_deg: float = 2.0             # the still period ends early if the heading moves this much
    max_gap_s: float = 0.5                    # IMU stamps further apart: a time gap, s
    gap_rate_sigma_rad_s: float = 0.05        # heading sigma grows by this x the gap length, rad/s
    # output heading
    heading_correction: bool = True           # False: pure dead reckoning from the initial compass
    gate: GateConfig = field(default_factory=GateConfig)  # magnetic gate thresholds
    heading: HeadingFilterConfig = field(default_factory=HeadingFilterConfig)  # output heading filter

    def model(self) -> DriftModel:
        terms = tuple(self.terms) + (SCALE_FACTOR_TERMS if self.scale_factor else ())
        return DriftModel(terms, self.temperature_ref_c)


@dataclass(frozen=True)
class ThermalOutput:
    """Per IMU sample: the heading track plus what a ROS node publishes."""
    track: HeadingTrack
    gyro_compensated: np.ndarray   # (N, 3) rad/s: z minus D_hat, x/y minus still-period bias
    temperature_c: np.ndarray      # (N,) smoothed, NaN before any temperature arrived
    temperature_rate_c_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    gate_open: np.ndarray          # (N,) bool
    reasons: np.ndarray            # (N,) bit mask over REASONS
    params: np.ndarray             # (N, n) drift-model parameters in force
    param_sigmas: np.ndarray       # (N, n)
    valid: np.ndarray              # (N,) False where the input row was dropped


def reason_names(mask: int) -> list[str]:
    return [name for name in REASONS if int(mask) & REASON_BIT[name]]


class _BinnedMean:
    """Mean of (t, v) rows over roughly the trailing `window_s`, from `bin_s` bins on the absolute
    time grid (so chunking cannot change it): the completed bins of the window plus the current
    partial bin up to each sample. O(1) state per bin, cheap for single-sample calls."""

    def __init__(self, window_s: float, width: int, bin_s: float = 1.0):
        self.bin_s = float(bin_s)
        self.n_bins = max(1, int(round(window_s / bin_s)))
        self.bins: deque = deque()            # (sum (width,), count) of completed bins
        self.total = np.zeros(width)
        self.count = 0.0
        self.cur_id = None
        self.cur_sum = np.zeros(width)
        self.cur_n = 0.0

    def update(self, t: np.ndarray, v: np.ndarray, use: np.ndarray | None = None) -> np.ndarray:
        """Means at each sample; rows with use == False do not enter the average (a sample with
        nothing usable yet gets its own value)."""
        w = np.ones(t.size) if use is None else use.astype(float)
        vw = v * w[:, None]
        out = v.copy()
        if t.size == 0:
            return out
        ids = np.floor(t / self.bin_s).astype(np.int64)
        if ids[0] == ids[-1]:
            bounds = [0, t.size]  # one bin: the usual case for small chunks
        else:
            bounds = list(np.flatnonzero(np.diff(ids, prepend=ids[0] - 1) != 0)) + [t.size]
        for k in range(len(bounds) - 1):
            i0, i1 = bounds[k], bounds[k + 1]
            if self.cur_id is not None and ids[i0] != self.cur_id:
                self._complete()
            self.cur_id = int(ids[i0])
            cs = np.cumsum(vw[i0:i1], axis=0) + self.cur_sum
            cn = self.cur_n + np.cumsum(w[i0:i1])
            den = cn + self.count
            ok = den > 0
            out[i0:i1][ok] = (cs[ok] + self.total) / den[ok, None]
            self.cur_sum, self.cur_n = cs[-1].copy(), float(cn[-1])
        return out

    def snapshot(self) -> tuple:
        return (list(self.bins), self.total.copy(), self.count, self.cur_id, self.cur_sum.copy(), self.cur_n)

    def restore(self, snap: tuple) -> None:
        bins, self.total, self.count, self.cur_id, self.cur_sum, self.cur_n = snap
        self.bins = deque(bins)

    def _complete(self) -> None:
        self.bins.append((self.cur_sum, self.cur_n))
        self.total = self.total + self.cur_sum
        self.count += self.cur_n
        if len(self.bins) > self.n_bins:
            s, n = self.bins.popleft()
            self.total = self.total - s
            self.count -= n
        self.cur_sum = np.zeros_like(self.cur_sum)
        self.cur_n = 0.0


def _clean(t: np.ndarray, values: list[np.ndarray], t_last: float) -> tuple[np.ndarray, int, int]:
    """Mask of usable samples: all finite and stamp strictly after every earlier stamp."""
    if t.size == 1:  # live single-sample path
        finite = bool(np.isfinite(t[0])) and all(bool(np.all(np.isfinite(v))) for v in values)
        ordered = bool(t[0] > t_last) if finite or np.isfinite(t[0]) else False
        return np.array([finite and ordered]), int(not finite), int(finite and not ordered)
    finite = np.isfinite(t)
    for v in values:
        finite &= np.all(np.isfinite(v.reshape(t.size, -1)), axis=1)
    tt = np.where(np.isfinite(t), t, -np.inf)
    prev_max = np.maximum.accumulate(np.concatenate(([t_last], tt)))[:-1]
    ordered = tt > prev_max
    ok = finite & ordered
    return ok, int(np.count_nonzero(~finite)), int(np.count_nonzero(finite & ~ordered))


class ThermalDriftEstimator:
    """STKF thermal-drift heading estimator; implements `HeadingMethod` (`name`, `update`).

    `process(chunk)` returns the richer `ThermalOutput`; `get_state`/`set_state` persist and warm
    start the parameters; `diagnostics()` is a snapshot for a node. `learner_factory(x0, P0, Q)`
    and `fixed_params` let the baselines reuse the whole pipeline with another parameter learner.
    """

    def __init__(self, config: EstimatorConfig = EstimatorConfig(),
                 learner_factory: Callable[..., object] | None = None, fixed_params=None):
        cfg = config
        if not 0 <= cfg.confirm_s < cfg.window_s:
            raise ValueError('confirm_s must be in [0, window_s)')
        self.cfg = cfg
        self.name = cfg.name
        self.model = cfg.model()
        n = len(self.model)
        self._arw = math.radians(cfg.arw_deg_sqrt_s)
        self._learner_factory = learner_factory
        self._fixed = None if fixed_params is None else np.asarray(fixed_params, dtype=float).reshape(n)
        self.learner = None                   # StrongTrackingKF (or a baseline learner) once started
        self._warm: dict | None = None
        self.temp = TemperatureRateEstimator(cfg.temp_window_s, stuck_after_s=cfg.temp_stuck_s,
                                             hold_max_s=cfg.temp_hold_max_s)
        self.gate = MagneticGate(replace(cfg.gate, reference_s=cfg.still_period_s,
                                         arw_deg_sqrt_s=cfg.arw_deg_sqrt_s))
        self.heading = HeadingFilter(replace(cfg.heading, arw_rad_sqrt_s=self._arw))
        self._accel = _BinnedMean(cfg.tilt_window_s, 3)
        self._tilt_max_rate = math.radians(cfg.gate.turn_rate_deg_s)
        # compass blocks tile the update windows exactly
        self._block_s = cfg.window_s / max(1, round(cfg.window_s / cfg.compass_block_s))
        self._omega_up = 0.0 if cfg.latitude_deg is None else \
            EARTH_RATE_RAD_S * math.sin(math.radians(cfg.latitude_deg))
        # time and integration state
        self.t_origin: float | None = None
        self._t_imu = -np.inf                 # latest accepted IMU stamp
        self._t_mag = -np.inf                 # latest accepted compass stamp
        self._psi_g = 0.0                     # gyro heading (continuous, rad)
        self._last_imu: dict | None = None    # values of the latest IMU sample (for compass lookups)
        self._bias_xy = np.zeros(2)
        self._temp_fallback = cfg.temperature_ref_c
        # still period
        self._still_end: float | None = None
        self._still = {'n': 0, 'sum': np.zeros(3), 'tsum': 0.0, 'tn': 0, 'psi0': None, 'z': []}
        self._started = False
        # STKF windows
        self._win: DriftWindow | None = None
        self._i_d = 0.0                       # int g D_hat dt since the window start, rad
        self._i_h = np.zeros(n)               # int g H dt since the window start
        self._pending: dict | None = None     # measurement awaiting confirmation
        self._t_last_closed = -np.inf         # end of the latest gate-closed compass block
        self._t_last_gap = -np.inf
        self._sigma_d = 0.0                   # 1-sigma of D_hat at the current temperature, rad/s
        self._innov = deque(maxlen=cfg.innovation_windows)  # recent accepted (gamma, S) of the learner
        self._compass_var = math.radians(cfg.compass_sigma_deg or cfg.compass_sigma_default_deg) ** 2
        # compass blocks and heading filter
        self._block_buf: dict[str, np.ndarray] | None = None
        self._mag_pending = (np.empty(0), np.empty((0, 3)))  # compass before the first IMU sample
        self._closed_until = -np.inf          # end of the latest processed compass block
        self._hf_t: float | None = None       # heading filter propagated to this time
        self._gap_jump = False
        self._rec = {'t': -np.inf, 'off': 0.0, 'var': math.pi ** 2, 'tau': 0.0, 'open': False, 'reasons': 0}
        self._records: list[dict] = []       # heading-filter outputs per block, not yet used
        self._rec_used = dict(self._rec)
        self._last_row: dict | None = None
        self.window_log: list[dict] = []      # every drift measurement formed (MLR, analysis)
        self.stats = {'imu_dropped_nan': 0, 'imu_dropped_order': 0, 'mag_dropped_nan': 0,
                      'mag_dropped_order': 0, 'mag_dropped_late': 0, 'time_gaps': 0,
                      'windows_used': 0, 'windows_rejected': 0, 'windows_gated': 0, 'coasting_s': 0.0}

    # ------------------------------------------------------------------ persistence / warm start
    def get_state(self) -> dict:
        """Parameters and covariance (plain data) with the model they belong to."""
        n = len(self.model)
        st = {'terms': list(self.model.names), 'temperature_ref_c': self.model.temperature_ref_c}
        if self.learner is not None:
            st.update({'x': self.learner.x.tolist(), 'P': self.learner.P.tolist()})
        elif self._fixed is not None:
            st.update({'x': self._fixed.tolist(), 'P': np.zeros((n, n)).tolist()})
        elif self._warm is not None:
            st.update(self._warm)
        return st

    def set_state(self, state: dict) -> None:
        """Before the still period ends: warm start (`constant` is re-measured there, the other
        parameters and their covariance are kept). After: replaces the running parameters."""
        if list(state.get('terms', self.model.names)) != list(self.model.names):
            raise ValueError(f"state terms {state.get('terms')} do not match the model {self.model.names}")
        t_ref = float(state.get('temperature_ref_c', self.model.temperature_ref_c))
        if t_ref != self.model.temperature_ref_c:
            raise ValueError('state temperature_ref_c differs from the model')
        x = np.asarray(state['x'], dtype=float).reshape(-1)
        P = None if state.get('P') is None else np.asarray(state['P'], dtype=float)
        if x.size != len(self.model) or not np.all(np.isfinite(x)):
            raise ValueError('state x must hold one finite value per model term')
        if self.learner is not None:
            self.learner.set_state(x, P)
            self._update_sigma_d()
        else:
            self._warm = {'x': x.tolist(), 'P': None if P is None else P.tolist()}

    @property
    def params(self) -> np.ndarray:
        """Drift-model parameters in force (SI units, order of `model.names`)."""
        if self._fixed is not None:
            return self._fixed.copy()
        if self.learner is not None:
            return self.learner.x
        return np.zeros(len(self.model))

    def _param_sigmas(self) -> np.ndarray:
        if self.learner is None or self._fixed is not None:
            return np.full(len(self.model), np.nan)
        return np.sqrt(np.maximum(np.diag(self.learner.P), 0.0))

    # ------------------------------------------------------------------ HeadingMethod
    def update(self, chunk: SensorChunk) -> HeadingTrack:
        return self.process(chunk).track

    def process(self, chunk: SensorChunk) -> ThermalOutput:
        """Consume one chunk (time order); one output row per `chunk.imu` sample."""
        cfg = self.cfg
        imu = chunk.imu
        n_rows = 0 if imu is None else imu.t.size
        # 1. clean inputs
        if n_rows:
            ok, bad_nan, bad_order = _clean(imu.t, [imu.gyro, imu.accel], self._t_imu)
            self.stats['imu_dropped_nan'] += bad_nan
            self.stats['imu_dropped_order'] += bad_order
            ti, gyro, acc = imu.t[ok], imu.gyro[ok], imu.accel[ok]
        else:
            ok = np.zeros(0, dtype=bool)
            ti, gyro, acc = np.empty(0), np.empty((0, 3)), np.empty((0, 3))
        t_mag_before = self._t_mag
        tm, fm = np.empty(0), np.empty((0, 3))
        mag = chunk.mag
        if mag is not None and mag.t.size:
            okm, bad_nan, bad_order = _clean(mag.t, [mag.field], self._t_mag)
            self.stats['mag_dropped_nan'] += bad_nan
            self.stats['mag_dropped_order'] += bad_order
            tm, fm = mag.t[okm], mag.field[okm]
            if tm.size:
                self._t_mag = float(tm[-1])
            late = tm < self._closed_until  # its compass block was already processed
            self.stats['mag_dropped_late'] += int(np.count_nonzero(late))
            tm, fm = tm[~late], fm[~late]
        if self.t_origin is None and (ti.size or tm.size):
            # time origin (grid of windows and blocks, still period): the first sample of either
            self.t_origin = float(min(ti[0] if ti.size else np.inf, tm[0] if tm.size else np.inf))
            self._still_end = self.t_origin + cfg.still_period_s
        # 2. temperature, causally at the IMU stamps
        before = self.temp.last
        if chunk.temperature is not None and chunk.temperature.t.size:
            t_est = self.temp.update(chunk.temperature.t, chunk.temperature.temp_c)
        else:
            t_est = TemperatureEstimate(np.empty(0), np.empty(0), np.empty(0))
        temp_c, temp_rate, temp_ok = self.temp.at(t_est, ti, before)
        temp_c = np.where(temp_ok, temp_c, self._temp_fallback)  # before any reading: last / t_ref
        if np.any(temp_ok):
            self._temp_fallback = float(temp_c[temp_ok][-1])
        # 3. stretches between filter events, vectorised
        segs = []
        i = j = 0
        while i < ti.size or j < tm.size:
            tick = self._next_tick()
            i_end = i + int(np.searchsorted(ti[i:], tick, side='left'))
            j_end = j + int(np.searchsorted(tm[j:], tick, side='left'))
            if i_end > i or j_end > j:
                args = (ti[i:i_end], gyro[i:i_end], acc[i:i_end], temp_c[i:i_end],
                        temp_rate[i:i_end], temp_ok[i:i_end])
                stop = self._still_motion(*args[:3]) if not self._started and i_end > i else None
                if stop is not None:
                    # the unit moved: the still period ends at sample `stop` (inclusive)
                    i_end = i + stop + 1
                    self._still_end = float(ti[i_end - 1])
                    tick = self._still_end
                    j_end = j + int(np.searchsorted(tm[j:j_end], tick, side='left'))
                    args = tuple(a[:stop + 1] for a in args)
                segs.append(self._segment(*args, tm[j:j_end], fm[j:j_end]))
                i, j = i_end, j_end
            if i < ti.size or j < tm.size:
                self._close_blocks(tick)
                self._fire_tick(tick)
        # 4. one row per input sample
        return self._assemble([s for s in segs if s is not None], ok, imu, tm, t_mag_before)

    # ------------------------------------------------------------------ filter events
    def _next_tick(self) -> float:
        if self.t_origin is None:
            return np.inf
        if not self._started:
            return self._still_end
        if self._pending is not None:
            return min(self._win.t1, self._pending['confirm_at'])
        return self._win.t1

    def _fire_tick(self, tick: float) -> None:
        if not self._started:
            self._start(tick)
            return
        p = self._pending
        if p is not None and tick >= p['confirm_at']:
            self._pending = None
            clean = self._t_last_closed <= p['t0'] and self._t_last_gap < p['t0']
            if not clean:
                self.stats['windows_gated'] += 1
            self._learn(p['meas'] if clean else None, tick)
        w = self._win
        if tick >= w.t1:
            meas = w.measurement(self._arw, self._compass_var, self.cfg.r_floor_rad_s ** 2)
            clean = self._t_last_closed <= w.t0 and self._t_last_gap < w.t0
            if meas is not None:
                self.window_log.append({'t0': w.t0, 't1': w.t1, 'y': meas[0], 'h': meas[1].copy(),
                                        'R': meas[2], 'clean': clean})
            if meas is not None and clean:
                self._pending = {'meas': meas, 't0': w.t0, 'confirm_at': w.t1 + self.cfg.confirm_s}
                if self.cfg.confirm_s == 0:
                    self._fire_tick(tick)
            else:
                self.stats['windows_gated'] += int(meas is not None)
                self._learn(None, tick)
            self._new_window(w.t1, w.t1 + self.cfg.window_s)

    def _learn(self, meas, t: float) -> None:
        if self.learner is None or not self.cfg.learn or self._fixed is not None:
            return
        if meas is None:
            self.learner.step(None)
        else:
            x_before = self.learner.x
            res = self.learner.step(meas[0], meas[1], meas[2])
            self.stats['windows_used' if res.accepted else 'windows_rejected'] += 1
            if res.accepted and np.isfinite(res.innovation) and np.isfinite(res.innovation_var):
                self._innov.append((res.innovation, res.innovation_var))
            # the gate must not read the estimator's own correction as interference
            self.gate.rebase(float(self._live_row() @ (self.learner.x - x_before)), t)
        self._update_sigma_d()

    def _live_row(self) -> np.ndarray:
        """Regressor row at the live temperature and rate (no turn)."""
        last = self._last_imu or {}
        temp = float(last.get('temp_f', self.cfg.temperature_ref_c))
        return self.model.rows(_inputs(np.array([temp]), np.array([float(last.get('temp_rate', 0.0))]),
                                       np.zeros(1)))[0]

    def _update_sigma_d(self) -> None:
        if self.learner is None or self._fixed is not None:
            return
        # at the live temperature and rate: coasting into a ramp makes b and a uncertain in D_hat
        h = self._live_row()
        var = max(h @ self.learner.P @ h, 0.0)
        # the filter's P knows nothing of model error: a drift estimate lagging a ramp leaves
        # recent innovations of one sign, so their mean beyond what white noise explains is added.
        # (Their mean square would not do: over 30 windows it scatters by a quarter of S, and that
        # scatter alone would read as a drift uncertainty of half the window noise.)
        if len(self._innov) >= 2:
            g = np.asarray(self._innov)
            var += max(float(np.mean(g[:, 0])) ** 2 - float(np.mean(g[:, 1])) / len(g), 0.0)
        self._sigma_d = float(np.sqrt(var))

    def _new_window(self, t0: float, t1: float) -> None:
        self._win = DriftWindow(t0, t1, self.cfg.edge_s, len(self.model))
        self._i_d = 0.0
        self._i_h = np.zeros(len(self.model))

    def _start(self, t_start: float) -> None:
        """End of the still period: biases, initial parameters, compass noise; first window."""
        cfg = self.cfg
        st = self._still
        dur = max(t_start - self.t_origin, 1e-3)
        mean_w = st['sum'] / st['n'] if st['n'] else np.zeros(3)
        self._bias_xy = mean_w[:2].copy()
        t0 = st['tsum'] / st['tn'] if st['tn'] else self._temp_fallback
        if cfg.compass_sigma_deg is None and st['z']:
            tz = np.concatenate(st['z'], axis=0)
            if tz.shape[0] >= 10:
                tt = tz[:, 0] - tz[0, 0]
                resid = tz[:, 1] - np.polyval(np.polyfit(tt, tz[:, 1], 1), tt)
                self._compass_var = max(float(np.var(resid)), math.radians(cfg.compass_sigma_floor_deg) ** 2)
        st['z'] = []
        prior = np.asarray(cfg.prior_sigmas, dtype=float) if cfg.prior_sigmas else self.model.prior_sigmas()
        P0 = np.diag(prior ** 2)
        known = {}
        if self._warm is not None:
            known = {nm: float(v) for nm, v in zip(self.model.names, self._warm['x']) if nm != 'constant'}
            if self._warm.get('P') is not None:
                P0 = np.asarray(self._warm['P'], dtype=float).copy()
        x0 = self.model.initial_state(float(mean_w[2]), t0, known)
        i_c = self.model.index('constant')
        if i_c is not None:
            P0 = _still_covariance(P0, i_c, self.model.rows(_inputs(np.array([t0]), np.zeros(1),
                                                                       np.zeros(1)))[0],
                                   self._arw ** 2 / dur + cfg.r_floor_rad_s ** 2)
        if self._learner_factory is not None:
            self.learner = self._learner_factory(x0, P0, self._q_matrix())
        else:
            self.learner = StrongTrackingKF(x0, P0, self._q_matrix(), fading_s=cfg.fading_s,
                                            adaptive=cfg.adaptive_fading, reject_sigma=cfg.reject_sigma,
                                            p_max=np.maximum(np.diag(P0), prior ** 2))
        self._started = True
        self._update_sigma_d()
        # first window: from now to a window grid point at least half a window away
        k = math.ceil((t_start - self.t_origin) / cfg.window_s - 1e-9)
        t1 = self.t_origin + k * cfg.window_s
        if t1 - t_start < 0.5 * cfg.window_s:
            t1 += cfg.window_s
        self._new_window(t_start, t1)

    def _q_matrix(self) -> np.ndarray:
        q = np.asarray(self.cfg.q_sigmas, dtype=float) if self.cfg.q_sigmas else self.model.q_sigmas()
        return np.diag(q ** 2 * self.cfg.window_s)

    # ------------------------------------------------------------------ vectorised stretch
    def _heading_rate(self, t, gyro, acc, d_hat, bias_xy):
        """dt to integrate (0 across gaps), tilt, compensated rates and heading rate."""
        dt = np.diff(np.concatenate(([self._t_imu], t)))
        dt[~np.isfinite(dt)] = 0.0
        gap = dt > self.cfg.max_gap_s
        wc = np.column_stack((gyro[:, :2] - bias_xy, gyro[:, 2] - d_hat))
        # gravity = long-term mean specific force, without turning samples (centripetal force)
        acc_mean = self._accel.update(t, acc, np.abs(wc[:, 2]) < self._tilt_max_rate)
        roll, pitch = roll_pitch_from_accel(acc_mean)
        # the gate's tilt test: | |f| - g |, blind to the level accelerations a car makes all the
        # time (those are averaged out of the tilt by the long window instead)
        accel = np.abs(np.linalg.norm(acc, axis=1) - STANDARD_GRAVITY_M_S2)
        # ZYX yaw rate is (sin(roll) w_y + cos(roll) w_z) / cos(pitch). The w_y term is dropped: it
        # carries the y gyro's own thermal drift (only its start bias is known) into the heading,
        # sin(1 deg) x 0.5 deg/s = 0.01 deg/s, while the true sin(roll) w_y is second order in roll.
        g_tilt = np.cos(roll) / np.cos(pitch)
        rate = g_tilt * wc[:, 2] - self._omega_up
        return dt, gap, accel, roll, pitch, wc, rate, g_tilt

    def _still_drift(self, gyro):
        """During the still period the drift estimate is the running mean of the gyro so far."""
        st = self._still
        run = (np.cumsum(gyro, axis=0) + st['sum']) / (st['n'] + np.arange(1, gyro.shape[0] + 1))[:, None]
        return run[:, 2], run[:, :2]

    def _still_motion(self, t, gyro, acc):
        """Index of the first sample whose gyro heading left the start by `still_motion_deg`."""
        saved = self._accel.snapshot()  # a probe only: restore the accelerometer average after
        d_hat, bxy = self._still_drift(gyro)
        dt, gap, _, _, _, _, rate, _ = self._heading_rate(t, gyro, acc, d_hat, bxy)
        self._accel.restore(saved)
        psi = self._psi_g + np.cumsum(rate * np.where(gap, 0.0, dt))
        psi0 = self._still['psi0'] if self._still['psi0'] is not None else psi[0]
        moved = (np.abs(psi - psi0) > math.radians(self.cfg.still_motion_deg)) & (t < self._still_end)
        if not np.any(moved):
            return None
        k = int(np.argmax(moved))
        return k if k + 1 < t.size else None

    def _segment(self, t, gyro, acc, temp_c, temp_rate, temp_ok, tm, fm):
        """IMU then compass samples of one stretch with fixed parameters; returns output columns."""
        seg = None
        prev_imu = self._last_imu  # the IMU state before this stretch (for its compass samples)
        if t.size:
            n = t.size
            H = self.model.rows(_inputs(temp_c, temp_rate, gyro[:, 2]))
            if self._started:
                d_hat = H @ self.params
                bias_xy = self._bias_xy
            else:
                d_hat, bias_xy = self._still_drift(gyro)
                st = self._still
                st['n'] += n
                st['sum'] = st['sum'] + gyro.sum(axis=0)
                st['tsum'] += float(temp_c[temp_ok].sum())
                st['tn'] += int(np.count_nonzero(temp_ok))
            dt, gap, accel, roll, pitch, wc, rate, g_tilt = self._heading_rate(t, gyro, acc, d_hat, bias_xy)
            dt_int = np.where(gap, 0.0, dt)
            psi_g = self._psi_g + np.cumsum(rate * dt_int)
            if not self._started and self._still['psi0'] is None:
                self._still['psi0'] = float(psi_g[0])
            # the window integrals start at the window start, not at the sample before it
            dt_win = dt_int if self._win is None else np.minimum(dt_int, np.maximum(t - self._win.t0, 0.0))
            i_d = self._i_d + np.cumsum(g_tilt * d_hat * dt_win)
            i_h = self._i_h + np.cumsum((g_tilt * dt_win)[:, None] * H, axis=0)
            seg = {'t': t, 'psi_g': psi_g, 'd_hat': d_hat, 'wc': wc, 'rate': rate, 'roll': roll,
                   'pitch': pitch, 'temp': np.where(temp_ok, temp_c, np.nan), 'temp_rate': temp_rate,
                   'gap': gap, 'params': self.params,
                   'g_tilt': g_tilt, 'i_d': i_d, 'i_h': i_h, 'h': H, 'temp_f': temp_c,
                   'accel': accel}
            if np.any(gap):
                self.stats['time_gaps'] += int(np.count_nonzero(gap))
                self._t_last_gap = float(t[gap][-1])
                self._on_gap(float(dt[gap][-1]))
            self._last_imu = {k: seg[k][-1] for k in ('t', 'psi_g', 'rate', 'roll', 'pitch', 'accel',
                                                       'g_tilt', 'd_hat', 'i_d', 'i_h', 'h', 'temp_f',
                                                       'temp_rate')}
            self._t_imu = float(t[-1])
            self._psi_g = float(psi_g[-1])
            self._i_d = float(i_d[-1])
            self._i_h = i_h[-1].copy()
        if tm.size or (seg is not None and self._mag_pending[0].size):
            self._compass(tm, fm, seg, prev_imu)
        t_seen = max(self._t_imu if seg is not None else -np.inf, float(tm[-1]) if tm.size else -np.inf)
        self._close_blocks(t_seen)
        if seg is not None:
            seg.update(self._heading_at(seg['t'], seg['psi_g']))
        return seg

    def _on_gap(self, gap_s: float) -> None:
        """Nothing was integrated over the gap: inflate the heading variance, reset the mismatch
        history, and let the output take the next compass correction at once."""
        self.heading.inflate(min((self.cfg.gap_rate_sigma_rad_s * gap_s) ** 2, math.pi ** 2))
        self.gate.reset_mismatch()
        self._gap_jump = True

    def _compass(self, tm, fm, seg, prev) -> None:
        """Per compass sample: gyro heading there, compass heading, window and block bookkeeping.

        Each compass sample takes the gyro heading of the IMU sample strictly before it (so at equal
        stamps the compass goes first, in any chunking), extrapolated with that sample's rate.
        Compass samples before any IMU sample wait for the first one and take the start of the
        integration (psi_g = 0) with its gravity."""
        if prev is None and seg is None:
            # before any IMU sample: wait for the first one (its gravity levels the compass)
            self._mag_pending = (np.concatenate((self._mag_pending[0], tm)),
                                 np.concatenate((self._mag_pending[1], fm)))
            return
        if prev is None and self._mag_pending[0].size:
            tm = np.concatenate((self._mag_pending[0], tm))
            fm = np.concatenate((self._mag_pending[1], fm))
            self._mag_pending = (np.empty(0), np.empty((0, 3)))
        k = np.searchsorted(seg['t'], tm, side='left') - 1 if seg is not None else np.full(tm.size, -1)
        if prev is None:
            # compass samples at or before the first IMU sample: the start of the integration
            # (psi_g = 0 there) with that first sample's gravity
            prev = {key: seg[key][0] for key in seg if key not in ('temp', 'gap', 'params', 'wc')}
            prev['t'] = float(tm[0])
            prev['rate'] = 0.0

        def at(name):  # value of the IMU sample strictly before each compass sample
            if seg is None:
                return np.broadcast_to(prev[name], (tm.size,) + np.shape(prev[name])).copy()
            cur = seg[name][np.maximum(k, 0)]
            if prev is None or np.all(k >= 0):
                return cur
            sel = (k >= 0).reshape((-1,) + (1,) * (cur.ndim - 1))
            return np.where(sel, cur, prev[name])
        age = tm - at('t')
        rate, g_tilt, d_hat = at('rate'), at('g_tilt'), at('d_hat')
        psi_g = at('psi_g') + rate * age
        i_d = at('i_d') + g_tilt * d_hat * age
        i_h = at('i_h') + (g_tilt * age)[:, None] * at('h')
        if self._win is not None:
            # a compass sample at or just after a window start whose IMU sample precedes it: that
            # sample's integrals belong to the previous window; integrate from the window start
            old = at('t') < self._win.t0
            if np.any(old):
                since = np.maximum(tm - self._win.t0, 0.0)
                i_d = np.where(old, g_tilt * d_hat * since, i_d)
                i_h = np.where(old[:, None], (g_tilt * since)[:, None] * at('h'), i_h)
        reading = compass_heading(fm, None, self.cfg.declination_rad, roll_pitch=(at('roll'), at('pitch')))
        psi_c = np.atleast_1d(reading.heading_rad)
        if self._win is not None:
            self._win.add(tm, psi_g + i_d - psi_c, i_h)
        z = np.atleast_1d(wrap_angle(psi_c - psi_g))
        if not self._started:
            self._still['z'].append(np.column_stack((tm, z[0] + np.unwrap(z - z[0]))))
        if not self.heading.initialized:
            # the first compass sample defines the heading (and the deviation anchor psi0)
            self.heading.initialize(float(tm[0]), float(z[0]), float(psi_c[0]), self._compass_var,
                                    float(psi_g[0]))
            self._hf_t = float(tm[0])
            self._rec = {'t': float(tm[0]), 'off': float(z[0]), 'var': self._compass_var, 'tau': 0.0,
                         'open': True, 'reasons': 0}
            self._records.append({k: np.atleast_1d(v) for k, v in self._rec.items()})
        new = {'t': tm, 'z': z, 'psi_g': psi_g, 'norm': reading.field_norm_t, 'dip': reading.dip_rad,
               'acc': at('accel'), 'temp': at('temp_f')}
        buf = self._block_buf
        self._block_buf = new if buf is None else \
            {key: np.concatenate((buf[key], v)) for key, v in new.items()}

    def _close_blocks(self, t_seen: float) -> None:
        """Gate and heading filter over every compass block that ended by `t_seen`."""
        buf = self._block_buf
        if buf is None or buf['t'].size == 0:
            return
        bs = self._block_s
        if self.t_origin + (math.floor((buf['t'][0] - self.t_origin) / bs + 1e-9) + 1) * bs > t_seen:
            return  # the oldest open block has not ended yet
        bid = np.floor((buf['t'] - self.t_origin) / bs + 1e-9).astype(np.int64)
        nd = int(np.count_nonzero(self.t_origin + (bid + 1) * bs <= t_seen))  # a prefix: time order
        if nd == 0:
            return
        ids, first = np.unique(bid[:nd], return_index=True)
        counts = np.diff(np.append(first, nd))

        def mean(a):
            return np.add.reduceat(a[:nd], first) / counts
        z = buf['z'][:nd]
        z_ref = z[first]
        zb = z_ref + np.add.reduceat(np.atleast_1d(wrap_angle(z - np.repeat(z_ref, counts))), first) / counts
        tb = self.t_origin + (ids + 1) * bs
        psi_gb = mean(buf['psi_g'])
        res = self.gate.update(tb, mean(buf['norm']), mean(buf['dip']), wrap_angle(psi_gb + zb), psi_gb,
                               mean(buf['acc']), mean(buf['temp']), self._sigma_d,
                               compass_var_rad2=self._compass_var / counts)
        self._block_buf = {key: v[nd:] for key, v in buf.items()}
        self._closed_until = float(tb[-1])
        self._run_heading_filter(tb, zb, counts, psi_gb, res.open, res.reasons)

    def _run_heading_filter(self, tb, zb, counts, psi_gb, is_open, reasons) -> None:
        """Heading filter over closed compass blocks; keep one output record per block."""
        use = is_open & self.cfg.heading_correction
        out = self.heading.run(tb, zb, self._compass_var / counts, psi_gb, use, self._sigma_d,
                               jump=self._gap_jump)
        self._gap_jump = False
        # a refused compass block is coasting for the output heading. The drift windows follow the
        # gate only: after a long coast with a poor drift estimate the heading filter refuses the
        # compass until the drift is re-learned, and that must not wait for the heading filter (the
        # learner has its own innovation test)
        if np.any(~is_open):
            self._t_last_closed = float(tb[~is_open][-1])
        refused = use & (out[:, 3] == 0.0)
        if np.any(refused):
            reasons = reasons | np.where(refused, REASON_BIT['heading_innovation'], 0)
            is_open = is_open & ~refused
        closed = ~is_open
        if np.any(closed):
            dts = np.diff(np.concatenate(([self._hf_t], tb)))
            self.stats['coasting_s'] += float(np.sum(dts[closed]))
        self._hf_t = float(tb[-1])
        self._records.append({'t': tb, 'off': out[:, 0], 'var': out[:, 1], 'tau': out[:, 2],
                              'open': is_open, 'reasons': reasons})
        self._rec = {'t': float(tb[-1]), 'off': float(out[-1, 0]), 'var': float(out[-1, 1]),
                     'tau': float(out[-1, 2]), 'open': bool(is_open[-1]), 'reasons': int(reasons[-1])}

    def _heading_at(self, t, psi_g) -> dict:
        """Output heading at IMU stamps from the heading-filter record in force at each."""
        if not self._records and t.size and t[0] >= self._rec_used['t'] > -np.inf:
            r = self._rec_used  # no new record: one record for all stamps (the live path)
            age = t - r['t']
            tau = r['tau']
            var = r['var'] + self._arw ** 2 * age + self._sigma_d ** 2 * ((tau + age) ** 2 - tau ** 2)
            var = np.where(np.isfinite(var), np.minimum(var, math.pi ** 2), math.pi ** 2)
            return {'heading': np.atleast_1d(wrap_angle(psi_g + r['off'])), 'sigma': np.sqrt(var),
                    'open': np.full(t.size, bool(r['open'])),
                    'reasons': np.full(t.size, int(r['reasons']), dtype=np.int64)}
        # the latest record already in force, then those added since
        recs = [{k: np.atleast_1d(v) for k, v in self._rec_used.items()}] + self._records
        rec = {k: np.concatenate([np.atleast_1d(r[k]) for r in recs]) for k in recs[0]}
        idx = np.searchsorted(rec['t'], t, side='right') - 1  # records at or before each stamp
        have = idx >= 0
        j = np.maximum(idx, 0)
        t_rec = rec['t'][j]
        finite = np.isfinite(t_rec)
        age = np.where(have & finite, np.maximum(t - np.where(finite, t_rec, 0.0), 0.0), 0.0)
        tau = rec['tau'][j]
        var = rec['var'][j] + self._arw ** 2 * age + self._sigma_d ** 2 * ((tau + age) ** 2 - tau ** 2)
        var = np.where(have & np.isfinite(var), np.minimum(var, math.pi ** 2), math.pi ** 2)
        self._records = []
        self._rec_used = dict(self._rec)  # later stamps only need the latest record
        return {'heading': np.atleast_1d(wrap_angle(psi_g + np.where(have, rec['off'][j], 0.0))),
                'sigma': np.sqrt(var), 'open': rec['open'][j].astype(bool) & have,
                'reasons': np.where(have, rec['reasons'][j], 0).astype(np.int64)}

    # ------------------------------------------------------------------ output rows
    _ROW_KEYS = ('heading', 'sigma', 'd_hat', 'open', 'reasons', 'temp', 'temp_rate', 'roll', 'pitch',
                 'wc', 'params', 'gap')

    def _assemble(self, segs, ok, imu, tm, t_mag_before) -> ThermalOutput:
        n_par = len(self.model)
        n_rows = ok.size
        good = self._good_rows(segs, tm, t_mag_before) if segs else None
        if good is not None and good['t'].size == n_rows:
            rows = good  # nothing dropped: the common case
        else:
            rows = self._fill_dropped(good, ok)
        if good is not None:
            self._last_row = {key: good[key][-1] for key in self._ROW_KEYS}
        sig = self._param_sigmas()
        track = HeadingTrack(t=np.empty(0) if imu is None else imu.t.copy(), heading_rad=rows['heading'],
                             drift_rad_s=rows['d_hat'], heading_sigma_rad=rows['sigma'],
                             coasting=~rows['open'])
        return ThermalOutput(track=track, gyro_compensated=rows['wc'].reshape(n_rows, 3),
                             temperature_c=rows['temp'], temperature_rate_c_s=rows['temp_rate'],
                             roll_rad=rows['roll'], pitch_rad=rows['pitch'], gate_open=rows['open'],
                             reasons=rows['reasons'], params=rows['params'].reshape(n_rows, n_par),
                             param_sigmas=np.tile(sig, (n_rows, 1)), valid=ok.copy())

    def _good_rows(self, segs, tm, t_mag_before) -> dict:
        """Output columns of the accepted IMU samples, with the estimator's own reasons added."""
        n_par = len(self.model)
        if len(segs) == 1:
            s0 = segs[0]
            good = {key: s0[key] for key in self._ROW_KEYS + ('t',)}
            good['params'] = np.broadcast_to(s0['params'], (s0['t'].size, n_par))
        else:
            good = {key: np.concatenate([s[key] for s in segs]) for key in self._ROW_KEYS + ('t',)
                    if key != 'params'}
            good['params'] = np.concatenate([np.broadcast_to(s['params'], (s['t'].size, n_par))
                                             for s in segs])
        t = good['t']
        mag_t = np.concatenate(([t_mag_before], tm))
        last_mag = mag_t[np.maximum(np.searchsorted(mag_t, t, side='right') - 1, 0)]
        no_mag = t - last_mag > self.cfg.mag_timeout_s
        rs = good['reasons'] | np.where(no_mag, REASON_BIT['no_compass'], 0) | \
            np.where(good['gap'], REASON_BIT['time_gap'], 0) | \
            np.where(t < self._still_end, REASON_BIT['still_period'], 0)
        if self.temp.stuck:
            rs = rs | REASON_BIT['temperature_stuck']
        good['reasons'] = rs
        good['open'] = good['open'] & ~no_mag
        return good

    def _fill_dropped(self, good, ok) -> dict:
        """Rows for every input sample: a dropped one holds the latest good row before it (from
        this call, or the previous call's last row), flagged `dropped_input`."""
        prev = self._last_row or {'heading': 0.0, 'sigma': math.pi, 'd_hat': 0.0, 'open': False,
                                  'reasons': 0, 'temp': np.nan, 'temp_rate': 0.0, 'roll': 0.0,
                                  'pitch': 0.0, 'wc': np.zeros(3), 'params': self.params, 'gap': False}
        if ok.size == 0:
            return {key: np.zeros((0,) + np.shape(prev[key]), dtype=np.asarray(prev[key]).dtype)
                    for key in self._ROW_KEYS}
        pos = np.cumsum(ok) - 1
        rows = {}
        for key in self._ROW_KEYS:
            fill = np.asarray(prev[key])
            if good is None:
                rows[key] = np.broadcast_to(fill, (ok.size,) + fill.shape).copy()
            else:
                col = np.asarray(good[key])[np.maximum(pos, 0)]
                col[pos < 0] = fill
                rows[key] = col
        rows['reasons'] = np.where(ok, rows['reasons'], rows['reasons'] | REASON_BIT['dropped_input'])
        return rows

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self) -> dict:
        """Snapshot for a node's diagnostics: parameters, sigmas, gate, counters."""
        sig = self._param_sigmas()
        d = {'started': self._started, 'params': self.model.paper_coefficients(self.params),
             'param_sigmas': dict(zip(self.model.names, sig.tolist())),
             'drift_sigma_rad_s': self._sigma_d,
             'gate_open': bool(self._rec['open']), 'gate_reasons': reason_names(self._rec['reasons']),
             'coasting_for_s': float(self.heading.tau_coast), 'heading_sigma_rad': self.heading.sigma_rad,
             'temperature_stuck': self.temp.stuck, 'temperature_stuck_for_s': self.temp.stuck_for_s(),
             'temperature_dropped': self.temp.dropped_nan + self.temp.dropped_order,
             'compass_sigma_rad': math.sqrt(self._compass_var),
             'gate_reference': {'field_norm_t': self.gate.ref_norm, 'dip_rad': self.gate.ref_dip}}
        d.update(self.stats)
        if self.learner is not None:
            d['filter_updates'] = getattr(self.learner, 'n_updates', 0)
            d['filter_rejected'] = getattr(self.learner, 'n_rejected', 0)
        return d


def _still_covariance(P_prior: np.ndarray, i_c: int, h0: np.ndarray, var_still: float) -> np.ndarray:
    """Covariance after the still period measured the drift D0 = h0 . x at its temperature.

    The other parameters keep their prior P_oo; `constant` is c = D0 - sum_{j != c} h0_j x_j, so
    Var(c) = var_still + h0_o P_oo h0_o and Cov(x_o, c) = -P_oo h0_o. Measuring D0 at T0 != t_ref
    does not pin c itself, and a later innovation at T0 must not be pushed into `a`."""
    n = P_prior.shape[0]
    o = np.array([j for j in range(n) if j != i_c], dtype=int)
    P = np.zeros((n, n))
    P_oo = P_prior[np.ix_(o, o)]
    ph = P_oo @ h0[o]
    P[np.ix_(o, o)] = P_oo
    P[o, i_c] = P[i_c, o] = -ph
    P[i_c, i_c] = var_still + h0[o] @ ph
    return P


def _inputs(temp_c, temp_rate, rate) -> dict:
    return {'temperature': temp_c, 'temperature_rate': temp_rate, 'rate': rate}
