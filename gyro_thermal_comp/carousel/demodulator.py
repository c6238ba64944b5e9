"""Carousel rotation-modulation demodulator (design.md section 3; Kolesnyk & Chernyak, KPI 2023).

An IMU turns about its sensor z axis (the spin axis). Sensor-fixed in-plane errors then appear in the
body frame as a vector turning at the spin rate and average out over every whole revolution. This
core turns a stream of `SensorChunk`s into:

- one record per revolution (the paper's scheme): body-frame mean rate and specific force, the
  spin rate from the revolution period (subtracted from the axial gyro), the axial residual, and the
  current in-plane bias estimates; or pass-through records with a reason whenever rotation is too
  slow, irregular or interrupted, so output never stops;
- per-revolution in-plane gyro bias measurements for a thermal drift estimator (no compass needed);
- optionally every sample rotated into the body frame with the lock-in bias estimates removed.

Angle: the encoder (JointSamples.position, unwrapped rad, platform relative to body about +z) when
present, else the integrated axial gyro. Without an encoder the spin rate and the body's yaw rate
cannot be told apart from the axial gyro alone: the revolution period then includes body yaw and
the axial bias, and the axial output is ~0 unless `nominal_spin_rate_rad_s` is given (docs/carousel.md).

Pure numpy; no ROS imports. Pipeline: input hygiene -> alignment with encoder/aux streams (the main
IMU waits for them, bounded by timeouts) -> flip tracking (look-ahead guard_s) -> revolution core.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..samples import SensorChunk
from .buffers import Columns, StreamGate
from .config import CarouselConfig
from .flip import AXIS_INDEX, FlipTracker, SensorBiasBook, flip_rotation, platform_axis_to_imu
from .integrals import angle_integral, interpolate_at_angle, time_integral
from .lockin import LockInEstimator, RevolutionStats, solve
from .revolutions import Crossing, RevolutionLadder, rate_deviation

MAIN, AUX, NOAUX = 0, 1, 2          # sample source: main IMU, aux standing in, flip without aux
ENCODER, GYRO = 0, 1                # carousel angle source
DEMODULATED, PASS_THROUGH = 'demodulated', 'pass_through'
_EPS_T = 1e-9                       # s; windows shorter than this are not reported


@dataclass(frozen=True)
class RevolutionRecord:
    """One output interval [t_s - duration_s, t_s]. Vectors are body frame (REP 103)."""
    t_s: float                               # end of the revolution / interval, s
    duration_s: float
    rate_body_rad_s: np.ndarray              # (3,) mean angular rate, spin removed
    specific_force_body_m_s2: np.ndarray     # (3,) mean specific force
    spin_rate_rad_s: float                   # Omega estimate (signed, CCW about spin axis +)
    axial_residual_rad_s: float              # mean axial gyro - bias estimate - Omega (carousel z)
    gyro_bias_inplane_rad_s: np.ndarray      # (2,) platform x, y bias used (lock-in window)
    accel_bias_inplane_m_s2: np.ndarray      # (2,)
    gyro_bias_variance: float                # (rad/s)^2 per component of the lock-in estimate; inf if none
    mode: str                                # 'demodulated' | 'pass_through'
    reason: str                              # '' when demodulated
    angle_source: str                        # 'encoder' | 'gyro'
    flip_position: int                       # main IMU quarter turns about the flip axis
    aux_fraction: float                      # share of samples from the auxiliary IMU
    n_samples: int
    temperature_c: float | None              # mean gyro temperature over the interval


@dataclass(frozen=True)
class GyroBiasMeasurement:
    """A gyro bias measured over one whole clean revolution, imu_link axes; independent of other
    revolutions (no overlapping windows), so a Kalman filter may use each as one measurement.
    y = bias_rad_s with R = variance_rad2_s2 is the drift D of design.md eq. (1) for that axis,
    averaged over [t_s - duration_s, t_s]; H = [temperature_c, temperature_rate_c_s, 1]."""
    t_s: float                        # revolution end, s
    duration_s: float
    axis: str                         # 'x' | 'y' | 'z' of imu_link
    bias_rad_s: float
    variance_rad2_s2: float
    temperature_c: float | None       # mean over the revolution, deg C (None: no temperature stream)
    temperature_rate_c_s: float | None
    flip_position: int


@dataclass(frozen=True)
class HighRateSamples:
    """Every processed sample rotated into the body frame with the current bias estimates removed."""
    t: np.ndarray                     # (N,) s
    rate_body_rad_s: np.ndarray       # (N, 3)
    specific_force_body_m_s2: np.ndarray  # (N, 3)
    theta_rad: np.ndarray             # (N,) carousel angle used, unwrapped
    source: np.ndarray                # (N,) 0 main IMU, 1 auxiliary, 2 flip without auxiliary


@dataclass(frozen=True)
class DemodulatedOutput:
    records: tuple = ()               # RevolutionRecord, time order
    bias_measurements: tuple = ()     # GyroBiasMeasurement
    high_rate: HighRateSamples | None = None
    flip_events: tuple = ()           # FlipEvent completed during this update
    mode: str = PASS_THROUGH          # state after this update
    reason: str = 'no data yet'
    counts: dict = field(default_factory=dict)   # cumulative diagnostics counters


def records_as_arrays(records) -> dict:
    """Column view of records (for nodes, plots, evaluation)."""
    records = list(records)
    col = lambda name: np.array([getattr(r, name) for r in records])
    out = {name: col(name) for name in ('t_s', 'duration_s', 'spin_rate_rad_s', 'axial_residual_rad_s',
                                         'mode', 'reason', 'flip_position', 'n_samples')}
    out['rate_body_rad_s'] = np.array([r.rate_body_rad_s for r in records]).reshape(-1, 3)
    out['specific_force_body_m_s2'] = np.array([r.specific_force_body_m_s2 for r in records]).reshape(-1, 3)
    out['gyro_bias_inplane_rad_s'] = np.array([r.gyro_bias_inplane_rad_s for r in records]).reshape(-1, 2)
    out['accel_bias_inplane_m_s2'] = np.array([r.accel_bias_inplane_m_s2 for r in records]).reshape(-1, 2)
    return out


def _inplane(v: np.ndarray) -> np.ndarray:
    return v[..., 0] + 1j * v[..., 1]


class CarouselDemodulator:
    """Streaming demodulator: `update(chunk)` with chunks of any size, in time order; `flush()` at
    the end of data. Bad samples are dropped and counted (`counts`); outputs never contain NaN."""

    def __init__(self, config: CarouselConfig | None = None):
        self.config = cfg = config or CarouselConfig()
        self._r_cb = np.asarray(cfg.carousel_to_body, dtype=float).reshape(3, 3)
        self._aux_to_p = np.asarray(cfg.flip.aux_to_platform, dtype=float).reshape(3, 3)
        self.counts: Counter = Counter()
        self._gates = {name: StreamGate(name, self.counts) for name in ('imu', 'joint', 'imu_aux', 'temperature')}
        f3 = ((3,), float)
        self._pending = Columns({'t': ((), float), 'g': f3, 'a': f3})
        self._enc = Columns({'t': ((), float), 'pos': ((), float), 'vel': ((), float)})
        self._aux = Columns({'t': ((), float), 'g': f3, 'a': f3})
        self._temps = Columns({'t': ((), float), 'temp': ((), float)})
        self._aligned_spec = {'t': ((), float), 'g': f3, 'a': f3, 'theta_enc': ((), float),
                              'rate_enc': ((), float), 'enc_ok': ((), bool), 'g_aux': f3, 'a_aux': f3,
                              'aux_ok': ((), bool)}
        self._flip_buf = Columns(self._aligned_spec)
        self.book = SensorBiasBook(cfg.flip.axis)
        self._tracker = FlipTracker(cfg.flip.rate_threshold_rad_s, cfg.flip.guard_s,
                                    cfg.flip.initial_position, cfg.flip.max_angle_error_rad)
        self._n_flip_events = 0
        self._core_spec = {'t': ((), float), 'theta': ((), float), 'spin': ((), float), 'g': f3, 'a': f3,
                           'src': ((), np.int8), 'k': ((), np.int8), 'g_aux': f3, 'a_aux': f3,
                           'aux_ok': ((), bool)}
        self._buf = Columns(self._core_spec)
        self._ladder = RevolutionLadder(cfg.boundary_phase_rad)
        n = cfg.lockin_revolutions
        self._lockin = LockInEstimator(n, cfg.lockin_poly_order, cfg.lockin_max_span_s, cfg.bias_variance_floor)
        self._gyro_var = np.inf
        self._hist_t = np.empty(0)          # gyro-mode angle history for the spin-rate window
        self._hist_th = np.empty(0)
        # core state
        self._last_t: float | None = None
        self._last_ang: int | None = None
        self._last_theta = float(cfg.initial_angle_rad)
        self._last_gz = 0.0
        self._t_emit: float | None = None
        self._rev_start: Crossing | None = None
        self._stalled = False
        self._after = ''
        self._mode, self._reason = PASS_THROUGH, 'no data yet'
        self._out_records: list = []
        self._out_meas: list = []
        self._out_hr: list = []

    # ------------------------------------------------------------------ public API
    def update(self, chunk: SensorChunk) -> DemodulatedOutput:
        cfg = self.config
        if chunk.imu is not None and len(chunk.imu.t):
            s = chunk.imu
            keep = self._gates['imu'].filter(s.t, s.gyro, s.accel)
            self._pending.append(t=s.t[keep], g=s.gyro[keep], a=s.accel[keep])
        if chunk.joint is not None and len(chunk.joint.t) and cfg.angle_source == 'auto':
            s = chunk.joint
            keep = self._gates['joint'].filter(s.t, s.position)
            self._enc.append(t=s.t[keep], pos=s.position[keep], vel=s.velocity[keep])
        if chunk.imu_aux is not None and len(chunk.imu_aux.t) and cfg.flip.enabled:
            s = chunk.imu_aux
            keep = self._gates['imu_aux'].filter(s.t, s.gyro, s.accel)
            self._aux.append(t=s.t[keep], g=s.gyro[keep] @ self._aux_to_p.T,
                             a=s.accel[keep] @ self._aux_to_p.T)
        if chunk.temperature is not None and len(chunk.temperature.t):
            s = chunk.temperature
            keep = self._gates['temperature'].filter(s.t, s.temp_c)
            self._temps.append(t=s.t[keep], temp=s.temp_c[keep])
        pend = self._pending['t']
        if len(pend) and pend[-1] - pend[0] >= cfg.min_batch_s:   # output does not depend on batching
            self._pump(final=False)
        return self._collect()

    def flush(self) -> DemodulatedOutput:
        """Process everything still held back (waiting for encoder/aux data or flip look-ahead) and
        close the last partial interval as a pass-through record."""
        self._pump(final=True)
        if self._t_emit is not None and self._last_t is not None and self._last_t - self._t_emit > _EPS_T:
            self._emit_pass_through(self._t_emit, self._last_t, 'end of data: partial revolution')
            self._t_emit = self._last_t
        return self._collect()

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def reason(self) -> str:
        return self._reason

    # ------------------------------------------------------------------ front end
    def _collect(self) -> DemodulatedOutput:
        hr = None
        if self._out_hr:
            parts = self._out_hr
            hr = HighRateSamples(*(np.concatenate([p[i] for p in parts]) for i in range(5)))
        events = tuple(self._tracker.events[self._n_flip_events:])
        self._n_flip_events = len(self._tracker.events)
        out = DemodulatedOutput(tuple(self._out_records), tuple(self._out_meas), hr, events,
                                self._mode, self._reason, dict(self.counts))
        self._out_records, self._out_meas, self._out_hr = [], [], []
        return out

    def _releasable(self, final: bool) -> int:
        n = len(self._pending)
        if n == 0 or final:
            return n
        t = self._pending['t']
        frontier = np.inf
        if self.config.angle_source == 'auto' and self._gates['joint'].last_t == -np.inf:
            # Startup: give an encoder the chance to show up before settling for the gyro angle.
            if t[-1] - self._gates['imu'].first_t < self.config.encoder_timeout_s:
                return 0
        streams = [(self._enc, self.config.encoder_timeout_s)]
        if self.config.flip.enabled:
            streams.append((self._aux, self.config.flip.aux_timeout_s))
        for cols, timeout in streams:
            if len(cols):
                last = cols['t'][-1]
                if t[-1] - last <= timeout:      # stream alive: wait until it covers the IMU
                    frontier = min(frontier, last)
        return int(np.searchsorted(t, frontier, side='right'))

    def _pump(self, final: bool) -> None:
        while True:
            n = min(self._releasable(final), self.config.max_block_samples)
            if n == 0:
                break
            self._flip_stage(self._align(self._pending.take_front(n)), final=False)
        if final:
            self._flip_stage(None, final=True)

    @staticmethod
    def _interp_stream(cols: Columns, t: np.ndarray, max_gap: float, names) -> tuple:
        """Linear interpolation of stream columns at t; ok where bracketed by samples <= max_gap apart."""
        ok = np.zeros(len(t), bool)
        if len(cols) < 2:
            if len(cols) == 1:
                ok = t == cols['t'][0]
                return ok, [np.broadcast_to(cols[nm][0], (len(t),) + cols[nm].shape[1:]).copy()
                             for nm in names]
            return ok, [None for _ in names]
        ct = cols['t']
        j = np.clip(np.searchsorted(ct, t, side='right') - 1, 0, len(ct) - 2)
        span = ct[j + 1] - ct[j]
        ok = (t >= ct[0]) & (t <= ct[-1]) & (span <= max_gap)
        frac = np.clip((t - ct[j]) / span, 0.0, 1.0)
        vals = []
        for nm in names:
            c = cols[nm]
            f = frac.reshape((-1,) + (1,) * (c.ndim - 1))
            vals.append(c[j] + f * (c[j + 1] - c[j]))
        return ok, vals

    def _align(self, blk: dict) -> dict:
        cfg = self.config
        t = blk['t']
        n = len(t)
        out = dict(blk)
        out['theta_enc'] = np.zeros(n)
        out['rate_enc'] = np.zeros(n)
        out['enc_ok'] = np.zeros(n, bool)
        ok, (pos, vel) = self._interp_stream(self._enc, t, cfg.encoder_max_gap_s, ('pos', 'vel'))
        if np.any(ok):
            ct, cp = self._enc['t'], self._enc['pos']
            if len(ct) >= 2:
                j = np.clip(np.searchsorted(ct, t, side='right') - 1, 0, len(ct) - 2)
                slope = (cp[j + 1] - cp[j]) / (ct[j + 1] - ct[j])
                vel = np.where(np.isfinite(vel), vel, slope)   # JointState velocity may be absent
            else:
                vel = np.where(np.isfinite(vel), vel, 0.0)
            out['theta_enc'] = np.where(ok, pos, 0.0)
            out['rate_enc'] = np.where(ok, vel, 0.0)
            out['enc_ok'] = ok
        if len(self._enc):
            keep_from = max(int(np.searchsorted(self._enc['t'], t[-1], side='right')) - 1, 0)
            self._enc.drop_front(keep_from)
        out['g_aux'] = np.zeros((n, 3))
        out['a_aux'] = np.zeros((n, 3))
        out['aux_ok'] = np.zeros(n, bool)
        if cfg.flip.enabled:
            ok, (g, a) = self._interp_stream(self._aux, t, cfg.flip.aux_max_gap_s, ('g', 'a'))
            if np.any(ok):
                out['g_aux'] = np.where(ok[:, None], g, 0.0)
                out['a_aux'] = np.where(ok[:, None], a, 0.0)
                out['aux_ok'] = ok
            if len(self._aux):
                keep_from = max(int(np.searchsorted(self._aux['t'], t[-1], side='right')) - 1, 0)
                self._aux.drop_front(keep_from)
        return out

    def _flip_stage(self, al: dict | None, final: bool) -> None:
        cfg = self.config
        if not cfg.flip.enabled:
            if al is not None:
                n = len(al['t'])
                self._ingest(dict(al, src=np.zeros(n, np.int8), k=np.zeros(n, np.int8)))
            return
        ax = AXIS_INDEX[cfg.flip.axis]
        if al is not None and len(al['t']):
            main_r = al['g'][:, ax] - self.book.gyro[ax]
            aux_r = al['g_aux'][:, ax] - self.book.aux_offset()[0][ax]
            self._tracker.push(al['t'], main_r - np.where(al['aux_ok'], aux_r, 0.0))
            self._flip_buf.append(**al)
        flipping, position = self._tracker.release(final)
        n = len(flipping)
        if n == 0:
            return
        blk = self._flip_buf.take_front(n)
        src = np.where(flipping, np.where(blk['aux_ok'], AUX, NOAUX), MAIN).astype(np.int8)
        g, a = blk['g'].copy(), blk['a'].copy()
        for k in np.unique(position):
            sel = position == k
            rot = flip_rotation(cfg.flip.axis, k)
            g[sel], a[sel] = blk['g'][sel] @ rot.T, blk['a'][sel] @ rot.T
        aux = src == AUX
        g[aux], a[aux] = blk['g_aux'][aux], blk['a_aux'][aux]
        # Aux samples keep their own offsets; they are calibrated against the main IMU per window.
        blk.update(g=g, a=a, src=src, k=position.astype(np.int8))
        self._ingest(blk)

    # ------------------------------------------------------------------ revolution core
    def _bias_arrays(self, src: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample platform-frame (gyro, accel) bias estimates to subtract."""
        n = len(src)
        if n and k.min() == k.max() and not np.any(src == AUX):     # the common case, fast
            g, a = self.book.main_platform(int(k[0]))
            return np.broadcast_to(g, (n, 3)), np.broadcast_to(a, (n, 3))
        bg, ba = np.zeros((n, 3)), np.zeros((n, 3))
        for kk in np.unique(k):
            sel = (k == kk) & (src != AUX)
            if np.any(sel):
                g, a = self.book.main_platform(int(kk))
                bg[sel], ba[sel] = g, a
        aux = src == AUX
        if np.any(aux):
            bg[aux], ba[aux] = self.book.aux_offset()
        return bg, ba

    def _ingest(self, blk: dict) -> None:
        t = blk['t']
        if len(t) == 0:
            return
        ang = np.where(blk['enc_ok'], ENCODER, GYRO).astype(np.int8)
        prev_t = -np.inf if self._last_t is None else self._last_t
        prev_ang = ang[0] if self._last_ang is None else self._last_ang
        dt = np.diff(np.concatenate(([prev_t], t)))
        gap = dt > self.config.max_gap_s
        switch = ang != np.concatenate(([prev_ang], ang[:-1]))
        if self._last_t is None:
            gap[0] = False
        cuts = np.flatnonzero(gap | switch)
        bounds = np.concatenate(([0], cuts[cuts > 0], [len(t)]))
        for s, e in zip(bounds[:-1], bounds[1:]):
            if s in cuts and self._last_t is not None:
                if gap[s]:
                    self.counts['gaps'] += 1
                    self._restart(f'data gap of {dt[s]:.3f} s', gap=True)
                else:
                    self.counts['angle_source_switches'] += 1
                    names = ('encoder', 'gyro')
                    self._restart(f'angle source changed ({names[self._last_ang]} -> {names[ang[s]]})', gap=False)
            self._append_run({k: v[s:e] for k, v in blk.items()}, int(ang[s]), contiguous=not gap[s])

    def _restart(self, reason: str, gap: bool) -> None:
        """Forget the revolution in progress. After a gap the data before it is closed as a pass-through
        record (the gap itself is not covered); after an angle-source switch the samples stay and the
        next record simply spans the switch (the angle may jump, so no revolution can straddle it)."""
        if gap:
            if self._t_emit is not None and self._last_t - self._t_emit > _EPS_T:
                self._emit_pass_through(self._t_emit, self._last_t, reason)
            self._t_emit = None
            self._buf.clear()
        self._ladder.reset()
        self._rev_start = None
        self._stalled = False
        self._hist_t, self._hist_th = np.empty(0), np.empty(0)
        self._after = reason

    def _append_run(self, run: dict, ang: int, contiguous: bool) -> None:
        cfg = self.config
        t = run['t']
        bg, ba = self._bias_arrays(run['src'], run['k'])
        min_spin = 2.0 * np.pi / cfg.max_revolution_period_s
        if ang == ENCODER:
            theta, spin = run['theta_enc'], run['rate_enc']
        else:
            gz = run['g'][:, 2] - bg[:, 2]
            if contiguous and self._last_t is not None and len(self._hist_t):
                tt = np.concatenate(([self._last_t], t))
                gg = np.concatenate(([self._last_gz], gz))
                theta = self._last_theta + np.cumsum(0.5 * (gg[1:] + gg[:-1]) * np.diff(tt))
            else:       # start, or after a gap: cannot integrate across, continue from last angle
                theta = self._last_theta + np.concatenate(([0.0], np.cumsum(0.5 * (gz[1:] + gz[:-1]) * np.diff(t))))
            self._last_gz = float(gz[-1])
            # Spin rate for per-sample output: axial mean over a window (the gyro cannot separate
            # spin from body yaw); a rate too slow to complete a revolution counts as stopped.
            ht = np.concatenate((self._hist_t, t))
            hth = np.concatenate((self._hist_th, theta))
            t_back = np.maximum(t - cfg.gyro_spin_window_s, ht[0])
            span = t - t_back
            with np.errstate(invalid='ignore', divide='ignore'):
                spin = np.where(span > 0, (theta - np.interp(t_back, ht, hth)) / span, 0.0)
            spin = np.where(np.abs(spin) >= min_spin, spin, 0.0)
            if cfg.nominal_spin_rate_rad_s is not None:
                spin = np.where(spin != 0.0, cfg.nominal_spin_rate_rad_s, 0.0)
            keep = ht >= ht[-1] - cfg.gyro_spin_window_s - 1.0
            self._hist_t, self._hist_th = ht[keep], hth[keep]
        self._buf.append(t=t, theta=theta, spin=spin, g=run['g'], a=run['a'], src=run['src'], k=run['k'],
                         g_aux=run['g_aux'], a_aux=run['a_aux'], aux_ok=run['aux_ok'])
        self._last_t, self._last_ang, self._last_theta = float(t[-1]), ang, float(theta[-1])
        if self._t_emit is None:
            self._t_emit = float(t[0])
        done = 0
        for c in self._ladder.process(t, theta):
            # Samples up to a boundary get the estimates known before it, however the data is chunked.
            upto = int(np.searchsorted(t, c.t_s, side='right'))
            self._emit_high_rate(run, theta, spin, done, upto)
            done = upto
            self._advance_stall(c.t_s)
            self._on_boundary(c)
        self._emit_high_rate(run, theta, spin, done, len(t))
        self._advance_stall(float(t[-1]))

    def _emit_high_rate(self, run: dict, theta, spin, i0: int, i1: int) -> None:
        if not self.config.high_rate or i1 <= i0:
            return
        sl = slice(i0, i1)
        bg, ba = self._bias_arrays(run['src'][sl], run['k'][sl])
        self._out_hr.append(self._high_rate(run['t'][sl], theta[sl], spin[sl], run['g'][sl] - bg,
                                            run['a'][sl] - ba, run['src'][sl]))

    def _high_rate(self, t, theta, spin, g_c, a_c, src) -> tuple:
        rot = np.exp(1j * theta)
        zg, za = rot * _inplane(g_c), rot * _inplane(a_c)
        rate = np.column_stack((zg.real, zg.imag, g_c[:, 2] - spin)) @ self._r_cb.T
        sf = np.column_stack((za.real, za.imag, a_c[:, 2])) @ self._r_cb.T
        return t.copy(), rate, sf, theta.copy(), src.astype(np.int8)

    def _advance_stall(self, t_data: float) -> None:
        cfg = self.config
        if self._t_emit is None:
            return
        if not self._stalled and t_data - self._t_emit > cfg.max_revolution_period_s:
            self._stalled = True
        if self._stalled:
            if self._rev_start is None:
                why = (f'no revolution boundary within {cfg.max_revolution_period_s:g} s: '
                       'rotation too slow or stopped')
                if self._after:
                    why += f' (after {self._after})'
            else:
                why = f'rotation too slow: no full revolution within {cfg.max_revolution_period_s:g} s'
            while self._t_emit + cfg.pass_through_period_s <= t_data + _EPS_T:
                t_end = self._t_emit + cfg.pass_through_period_s
                self._emit_pass_through(self._t_emit, t_end, why)
                self._t_emit = t_end
            self._prune()

    def _on_boundary(self, c: Crossing) -> None:
        cfg = self.config
        if self._rev_start is None:
            why = 'acquiring first revolution' + (f' after {self._after}' if self._after else '')
            if c.t_s - self._t_emit > _EPS_T:
                self._emit_pass_through(self._t_emit, c.t_s, why)
        elif self._stalled:
            if c.t_s - self._t_emit > _EPS_T:
                self._emit_pass_through(self._t_emit, c.t_s, 'rotation resumed: last revolution spanned a stall')
        else:
            self._close_revolution(self._rev_start, c)
        self._rev_start = c
        self._t_emit = c.t_s
        self._stalled = False
        self._prune()

    def _prune(self) -> None:
        if len(self._buf):
            idx = int(np.searchsorted(self._buf['t'], self._t_emit, side='right')) - 1
            self._buf.drop_front(max(idx, 0))

    # ------------------------------------------------------------------ windows
    def _window(self, ta: float, tb: float, theta_ends: tuple | None) -> dict:
        """Samples of [ta, tb] with end points interpolated, bias estimates removed.

        theta_ends: exact boundary angles for a revolution (in-plane ends then use the same
        two-point model as the angle integral); None for pass-through (plain time interpolation)."""
        b = self._buf
        t_all = b['t']
        i0 = int(np.searchsorted(t_all, ta, side='right'))
        i1 = int(np.searchsorted(t_all, tb, side='left'))
        lo, hi = max(i0 - 1, 0), min(i1 + 1, len(t_all))
        sl = slice(lo, hi)
        t = t_all[sl]
        th = b['theta'][sl]
        src, k = b['src'][sl], b['k'][sl]
        bg, ba = self._bias_arrays(src, k)
        g, a = b['g'][sl] - bg, b['a'][sl] - ba
        spin = b['spin'][sl]
        zg, za = _inplane(g), _inplane(a)

        def end_point(tc, j, theta_c):
            """Values at time tc between local samples j and j+1."""
            if j + 1 >= len(t) or t[j + 1] == t[j]:
                return theta_c if theta_c is not None else th[j], zg[j], za[j], g[j, 2], a[j, 2], spin[j]
            f = (tc - t[j]) / (t[j + 1] - t[j])
            lin = lambda v: v[j] + f * (v[j + 1] - v[j])
            if theta_c is None:
                return lin(th), lin(zg), lin(za), lin(g[:, 2]), lin(a[:, 2]), lin(spin)
            return (theta_c, interpolate_at_angle(th[j], th[j + 1], zg[j], zg[j + 1], theta_c, f),
                    interpolate_at_angle(th[j], th[j + 1], za[j], za[j + 1], theta_c, f),
                    lin(g[:, 2]), lin(a[:, 2]), lin(spin))

        inner = slice(i0 - lo, i1 - lo)
        ja = i0 - 1 - lo
        jb = i1 - 1 - lo
        ea = end_point(ta, ja, None if theta_ends is None else theta_ends[0])
        eb = end_point(tb, jb, None if theta_ends is None else theta_ends[1])
        cat = lambda i, v: np.concatenate(([ea[i]], v[inner], [eb[i]]))
        return {'t': np.concatenate(([ta], t[inner], [tb])), 'theta': cat(0, th), 'zg': cat(1, zg),
                'za': cat(2, za), 'gz': cat(3, g[:, 2]), 'az': cat(4, a[:, 2]), 'spin': cat(5, spin),
                'inner': slice(lo + inner.start, lo + inner.stop)}

    def _window_sources(self, inner: slice) -> tuple[np.ndarray, np.ndarray]:
        return self._buf['src'][inner], self._buf['k'][inner]

    def _temperature(self, ta: float, tb: float) -> tuple[float | None, float | None]:
        tt, temp = self._temps['t'], self._temps['temp']
        if len(tt) == 0:
            return None, None
        # Time mean of the piecewise-linear temperature over [ta, tb] (held beyond the samples), so a
        # 1 Hz sensor still gives the right mean over a 0.25 s revolution.
        inside = (tt > ta) & (tt < tb)
        pts = np.concatenate(([ta], tt[inside], [tb]))
        mean = float(time_integral(pts, np.interp(pts, tt, temp)) / (tb - ta))
        rate = None
        recent = tt >= tb - self.config.temperature_rate_window_s
        recent &= tt <= tb
        if np.count_nonzero(recent) >= 2 and np.ptp(tt[recent]) > 0:
            rate = float(np.polyfit(tt[recent] - tb, temp[recent], 1)[0])
        old = max(int(np.searchsorted(tt, ta - self.config.temperature_rate_window_s)) - 1, 0)
        self._temps.drop_front(old)
        return mean, rate

    def _lockin_fields(self):
        k_now = self._tracker.position if self.config.flip.enabled else 0
        bg, ba = self.book.main_platform(k_now)
        return bg[:2].copy(), ba[:2].copy()

    def _record(self, ta, tb, rate_c, sf_c, spin, axial, mode, reason, ang, k, aux_frac, n, temp) -> None:
        bg, ba = self._lockin_fields()
        rate = self._r_cb @ np.asarray(rate_c, dtype=float)
        sf = self._r_cb @ np.asarray(sf_c, dtype=float)
        finite = np.all(np.isfinite(rate)) and np.all(np.isfinite(sf)) and np.isfinite(spin)
        if not finite:      # never propagate NaN: report the interval with zeros and say why
            self.counts['nonfinite_records'] += 1
            rate, sf, spin, axial = np.zeros(3), np.zeros(3), 0.0, 0.0
            mode, reason = PASS_THROUGH, 'numerical failure in interval (zeros reported)'
        self._out_records.append(RevolutionRecord(
            float(tb), float(tb - ta), rate, sf, float(spin), float(axial), bg, ba,
            float(self._gyro_var), mode, reason, ('encoder', 'gyro')[ang], int(k), float(aux_frac), int(n), temp))
        self._mode, self._reason = mode, reason
        self.counts['records_' + mode] += 1

    def _emit_pass_through(self, ta: float, tb: float, reason: str) -> None:
        w = self._window(ta, tb, None)
        dur = tb - ta
        src, k = self._window_sources(w['inner'])
        if np.any(src == NOAUX):
            reason = 'flip without auxiliary IMU; ' + reason
        rot = np.exp(1j * w['theta'])
        ig = time_integral(w['t'], rot * w['zg']) / dur
        ia = time_integral(w['t'], rot * w['za']) / dur
        spin = float(time_integral(w['t'], w['spin']) / dur)
        axial = float(time_integral(w['t'], w['gz']) / dur) - spin
        az = float(time_integral(w['t'], w['az']) / dur)
        self._aux_calibrate(w['inner'], dur)
        temp, _ = self._temperature(ta, tb)
        kk = int(k[-1]) if len(k) else 0
        self._record(ta, tb, (ig.real, ig.imag, axial), (ia.real, ia.imag, az), spin, axial, PASS_THROUGH,
                     reason, self._last_ang or 0, kk, float(np.mean(src == AUX)) if len(src) else 0.0,
                     len(src), temp)

    def _close_revolution(self, start: Crossing, end: Crossing) -> None:
        cfg = self.config
        ta, tb = start.t_s, end.t_s
        dur = tb - ta
        dth = end.level_rad - start.level_rad
        w = self._window(ta, tb, (start.level_rad, end.level_rad))
        src, k = self._window_sources(w['inner'])
        n = len(src)
        dev = rate_deviation(w['t'], w['theta'])
        reason = ''
        if n < cfg.min_samples_per_revolution:
            reason = f'revolution too short: {n} samples < {cfg.min_samples_per_revolution}'
        elif dur > cfg.max_revolution_period_s:
            reason = f'rotation too slow: revolution took {dur:.2f} s > {cfg.max_revolution_period_s:g} s'
        elif dev > cfg.max_rate_deviation:
            reason = (f'rotation irregular: spin rate deviated {100 * dev:.0f} % from the revolution mean '
                      f'(limit {100 * cfg.max_rate_deviation:.0f} %)')
        elif np.any(src == NOAUX):
            reason = 'flip without auxiliary IMU'
        if reason:
            self.counts['revolutions_rejected'] += 1
            self._emit_pass_through(ta, tb, reason)
            return
        self.counts['revolutions_demodulated'] += 1
        ig, ia = angle_integral(w['theta'], np.column_stack((w['zg'], w['za']))) / dth
        if self._last_ang == GYRO and cfg.nominal_spin_rate_rad_s is not None:
            spin = float(np.sign(dth) * abs(cfg.nominal_spin_rate_rad_s))
        else:
            spin = dth / dur      # the paper's spin estimate: one turn per revolution period
        axial = float(time_integral(w['t'], w['gz']) / dur) - spin
        az = float(time_integral(w['t'], w['az']) / dur)
        temp, temp_rate = self._temperature(ta, tb)
        kk = int(k[-1])
        clean = bool(np.all(src == MAIN) and np.all(k == k[0]))
        if clean:
            self._update_lockin(w['inner'], tb, dur, kk, temp, temp_rate)
        self._aux_calibrate(w['inner'], dur)
        self._record(ta, tb, (ig.real, ig.imag, axial), (ia.real, ia.imag, az), spin, axial, DEMODULATED, '',
                     self._last_ang, kk, float(np.mean(src == AUX)), n, temp)

    def _update_lockin(self, inner: slice, tb: float, dur: float, k: int, temp, temp_rate) -> None:
        cfg = self.config
        b = self._buf
        t, th = b['t'][inner], b['theta'][inner]
        g, a = b['g'][inner], b['a'][inner]
        tref = float(tb - 0.5 * dur)
        # Gyro and accelerometer share t and theta, hence one set of normal equations.
        stats = RevolutionStats.from_samples(t, th, np.column_stack((_inplane(g), _inplane(a))),
                                             max(cfg.lockin_poly_order, cfg.measurement_poly_order), tref)
        # Independent single-revolution measurement for the thermal estimator.
        single = solve([stats], cfg.measurement_poly_order, tref, cfg.bias_variance_floor)
        if single is not None:
            sg = single[0]
            for p_axis, value in ((0, sg.bias.real), (1, sg.bias.imag)):
                j, sign = platform_axis_to_imu(cfg.flip.axis, k, p_axis)
                self._out_meas.append(GyroBiasMeasurement(
                    float(tb), float(dur), 'xyz'[j], float(sign * value), float(sg.bias_variance),
                    temp, temp_rate, int(k)))
        self._lockin.add(stats, tag=k)
        sol = self._lockin.estimate(tb)
        if sol is not None:
            sol_g, sol_a = sol
            self.book.update_inplane(k, sol_g.bias, sol_a.bias, sol_g.bias_variance, sol_a.bias_variance, tb)
            self._gyro_var = sol_g.bias_variance

    def _aux_calibrate(self, inner: slice, dur: float) -> None:
        """Blend this interval's mean (aux - main) platform-frame difference into the book."""
        if not self.config.flip.enabled:
            return
        b = self._buf
        sel = b['aux_ok'][inner] & (b['src'][inner] == MAIN)
        k = b['k'][inner]
        if np.count_nonzero(sel) < 2 or np.any(k[sel] != k[sel][0]):
            return
        dg = np.mean(b['g_aux'][inner][sel] - b['g'][inner][sel], axis=0)
        da = np.mean(b['a_aux'][inner][sel] - b['a'][inner][sel], axis=0)
        weight = 1.0 - np.exp(-dur / self.config.flip.aux_calibration_tau_s)
        self.book.update_aux(int(k[sel][0]), dg, da, weight)
