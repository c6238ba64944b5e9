"""Streaming heading scorer: docs/design.md section 5, computed in one pass over hours of data.

What is scored, per method and per IMU sample (all internal quantities in rad, rad/s, s):

* Truth heading `psi_true`: yaw of `/ground_truth/odom` (ZYX, ENU, CCW from east), linearly
  interpolated to the IMU times. Yaw is made continuous first (each step wrapped by `wrap_angle`
  and accumulated), so interpolating across the +-pi seam never averages +pi and -pi into 0.
* Heading error `e = wrap(psi_est - psi_true) - e0`, where `e0` is its mean over the first
  `reference_window_s` (60 s) of scored samples. The wrapped difference is made continuous in time
  (each sample takes the 2*pi branch nearest to the previous error), so a method whose error grows
  past 180 deg keeps growing instead of jumping; whenever |e| < 180 deg this is exactly the
  docs/design.md formula.
* Oracle: the same gyro samples with the true drift removed, integrated (trapezoid rule) from the
  true heading at the first scored sample. The heading rate is the exact ZYX yaw kinematics
      psi_dot = (sin(roll) * w_y + cos(roll) * w_z) / cos(pitch)
  with w_z = gyro_z - D_true_z and roll, pitch, w_y from the truth. For a level unit this is just
  gyro_z - D_true_z. We use the yaw rate rather than the Earth-frame vertical component
  (R w)_z = psi_dot - sin(pitch) * roll_dot because the score compares ZYX yaw; the two differ
  when the unit rolls while pitched. Only the z gyro is taken from the sensor (x/y terms from the
  truth), so the oracle's error is the z gyro's non-drift error (angle random walk, plus whatever
  else the simulator puts in the gyro besides the drift, e.g. scale factor or Earth rate) and it
  stays valid when the sensor x/y axes spin relative to the body (carousel).
  Assumes the sensor (imu_link) z axis is the body z axis, as everywhere in the package; with a
  `joint` stream (vertical carousel) the joint rate is removed from gyro z first. Mounts that spin
  about a horizontal axis (sensor z not vertical) are not supported by the oracle.
* True drift `D_true`: z of `/ground_truth/gyro_bias`, linearly interpolated. If the gyro also
  senses the Earth rotation and the truth stream leaves it out, pass `earth_rate_enu_rad_s`
  (e.g. sim.earth.earth_rate_enu(lat)): its projection on body z is added to D_true, because a
  heading filter can only learn (and must remove) the sum. Without it that projection (up to
  15 deg/h * sin(lat)) shows up in the oracle error and in every bias error.
* Excess `e_method - e_oracle`: what imperfect drift estimation costs.
* Outage spans: IMU times where |mag_disturbance truth| > threshold (zero-order hold of the
  latest disturbance sample, so the stream must be published continuously, zeros included); each
  span's scores are outage_spans.py's.
* Bias error `D_hat - D_true` (z axis, rad/s) where the method reports `drift_rad_s`.
* Rate error for the Allan deviation: `gyro_z - D_hat - w_true_z` (w_true_z = odom body rate z);
  references: uncompensated `gyro_z - w_true_z` and oracle `gyro_z - D_true_z - w_true_z`.

Streaming: statistics are running sums merged batch by batch (Chan's parallel update of mean and
sum of squared deviations: stable, and order independent up to rounding); plots only get 1-s bin
means (and each bin's per-sample max |e|). Samples wait in a small pending buffer until truth
covering them has arrived (truth and IMU need not share chunk edges), and scored batches in the
reference window (reference_window.py) until the first 60 s (for e0) are complete.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Callable, Hashable, Mapping, Sequence

import numpy as np

from ..angles import euler_from_quat, wrap_angle
from ..heading_track import HeadingTrack
from ..samples import SensorChunk
from .outage_spans import OutageSpan, OutageSpans
from .reference_window import ReferenceWindow
from .scored_rows import ScoredRows

ORACLE = 'oracle'
RAW = 'uncompensated'
_MAX_UNTRUTHED_S = 120.0  # IMU time allowed to pile up before we conclude the stream has no odom


class ScoringError(ValueError):
    """Input that cannot be scored (no truth, mismatched method output)."""


# ----------------------------------------------------------------------------------------------
# Running statistics and decimated series
# ----------------------------------------------------------------------------------------------
@dataclass
class RunningStats:
    """Count, mean, population variance, RMS, min, max and max |x| of a stream of values.

    Non-finite values are skipped (counted in `n_skipped`). Batches merge with Chan's update, so
    the result equals a one-shot computation over the concatenated samples up to rounding.
    """
    n: int = 0
    n_skipped: int = 0
    _mean: float = 0.0
    _m2: float = 0.0          # sum of squared deviations from the mean
    min: float = np.inf
    max: float = -np.inf

    def add(self, x) -> None:
        x = np.asarray(x, dtype=float).reshape(-1)
        ok = np.isfinite(x)
        self.n_skipped += int(x.size - np.count_nonzero(ok))
        x = x[ok]
        nb = x.size
        if nb == 0:
            return
        mb = float(np.mean(x))
        m2b = float(np.sum((x - mb) ** 2))
        na, n = self.n, self.n + nb
        delta = mb - self._mean
        self._mean += delta * nb / n
        self._m2 += m2b + delta * delta * na * nb / n
        self.n = n
        self.min = min(self.min, float(np.min(x)))
        self.max = max(self.max, float(np.max(x)))

    @property
    def mean(self) -> float:
        return self._mean if self.n else np.nan

    @property
    def var(self) -> float:
        """Population variance (ddof=0)."""
        return self._m2 / self.n if self.n else np.nan

    @property
    def rms(self) -> float:
        return float(np.sqrt(self._mean ** 2 + self.var)) if self.n else np.nan

    @property
    def max_abs(self) -> float:
        return max(abs(self.min), abs(self.max)) if self.n else np.nan

    def summary(self, scale: float = 1.0) -> 'StatsSummary':
        """Plain numbers, values multiplied by `scale` (variance by scale**2); NaN when empty."""
        return StatsSummary(n=self.n, max_abs=self.max_abs * scale, mean=self.mean * scale,
                            var=self.var * scale ** 2, rms=self.rms * scale,
                            min=(self.min if self.n else np.nan) * scale,
                            max=(self.max if self.n else np.nan) * scale)


@dataclass(frozen=True)
class StatsSummary:
    """A `RunningStats` as plain numbers in one unit (`RunningStats.summary`); NaN when empty."""
    n: int
    max_abs: float
    mean: float
    var: float      # population variance, in the unit squared
    rms: float
    min: float
    max: float


class BinnedMeans:
    """Means of several channels over fixed time bins [t0 + i*bin_s, t0 + (i+1)*bin_s).

    Channels are named by any hashable key; all share one time base. Memory grows by one number per
    channel per bin (1 Hz: 3600 per hour), whatever the sample rate. Channels for which
    `keep_max_abs(key)` is true also keep each bin's max |x| (a bin mean hides the wander within it).
    """

    def __init__(self, t0_s: float, bin_s: float = 1.0, keep_max_abs: Callable[[Hashable], bool] = lambda key: False):
        self.t0_s, self.bin_s = float(t0_s), float(bin_s)
        self._keep_max_abs = keep_max_abs
        self._sum: dict[Hashable, np.ndarray] = {}
        self._count: dict[Hashable, np.ndarray] = {}
        self._max_abs: dict[Hashable, np.ndarray] = {}   # -inf: no finite sample in the bin
        self._size = 0

    def _grow(self, size: int) -> None:
        if size <= self._size:
            return
        new = max(size, 2 * self._size, 64)
        for store, fill in ((self._sum, 0.0), (self._count, 0.0), (self._max_abs, -np.inf)):
            for key, arr in store.items():
                store[key] = np.concatenate([arr, np.full(new - arr.size, fill)])
        self._size = new

    def add(self, t_s: np.ndarray, channels: Mapping[Hashable, np.ndarray]) -> None:
        """Add samples at times t_s: {channel: values (N,)}; non-finite values are skipped."""
        t_s = np.asarray(t_s, dtype=float)
        if t_s.size == 0:
            return
        idx = np.floor((t_s - self.t0_s) / self.bin_s).astype(np.int64)
        idx = np.maximum(idx, 0)
        lo, hi = int(idx.min()), int(idx.max()) + 1
        self._grow(hi)
        local = idx - lo  # bincount over this batch's bins only: cost independent of record length
        for key, x in channels.items():
            if key not in self._sum:
                self._sum[key] = np.zeros(self._size)
                self._count[key] = np.zeros(self._size)
                if self._keep_max_abs(key):
                    self._max_abs[key] = np.full(self._size, -np.inf)
            x = np.broadcast_to(np.asarray(x, dtype=float), t_s.shape)
            ok = np.isfinite(x)
            self._sum[key][lo:hi] += np.bincount(local[ok], weights=x[ok], minlength=hi - lo)
            self._count[key][lo:hi] += np.bincount(local[ok], minlength=hi - lo)
            if key in self._max_abs:
                np.maximum.at(self._max_abs[key][lo:hi], local[ok], np.abs(x[ok]))

    def n_bins(self) -> int:
        used = [np.flatnonzero(c) for c in self._count.values()]
        return max((int(u[-1]) + 1 for u in used if u.size), default=0)

    def centers_s(self) -> np.ndarray:
        return self.t0_s + (np.arange(self.n_bins()) + 0.5) * self.bin_s

    def counts(self, key: Hashable) -> np.ndarray:
        """Samples per bin of one channel (KeyError for a channel never added)."""
        return self._count[key][:self.n_bins()].copy()

    def mean(self, key: Hashable) -> np.ndarray:
        """Bin means of one channel, NaN in bins without a finite sample (KeyError for a channel
        never added)."""
        n = self.n_bins()
        c = self._count[key][:n]
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(c > 0, self._sum[key][:n] / np.where(c > 0, c, 1), np.nan)

    def max_abs(self, key: Hashable) -> np.ndarray:
        """Per-bin max |x| of a channel that keeps it, NaN in bins without a finite sample."""
        m = self._max_abs[key][:self.n_bins()]
        return np.where(np.isfinite(m), m, np.nan)


def allan_from_bin_means(bin_means: np.ndarray, counts: np.ndarray, bin_s: float):
    """Overlapping Allan deviation of a rate error from its bin means; returns (tau_s, adev).

    Why this is exact for tau >= bin_s: the Allan variance at tau = m*bin_s is half the mean square
    difference of consecutive tau-averages of the rate, and the average over m consecutive full bins
    *is* the average over that tau window (equal sample counts per bin at a uniform rate). The only
    difference from running `oadev` on the raw samples is the stride of the overlapping windows
    (bin_s instead of one sample period): same estimator in expectation, a little less averaging.
    Partial bins at the ends are dropped; empty interior bins (data gaps) are filled by linear
    interpolation of their neighbours, which keeps the time base uniform.
    """
    import allantools

    y = np.asarray(bin_means, dtype=float)
    c = np.asarray(counts, dtype=float)
    filled = c > 0
    if np.count_nonzero(filled) < 4:
        return np.array([]), np.array([])
    full = c >= 0.9 * np.median(c[filled])
    first, last = np.flatnonzero(full)[[0, -1]]
    y, ok = y[first:last + 1], (filled & np.isfinite(y))[first:last + 1]
    if np.count_nonzero(ok) < 4:
        return np.array([]), np.array([])
    if not ok.all():
        i = np.arange(y.size)
        y = np.interp(i, i[ok], y[ok])
    tau, adev, _, _ = allantools.oadev(y, rate=1.0 / bin_s, data_type='freq', taus='octave')
    return np.asarray(tau, dtype=float), np.asarray(adev, dtype=float)


class ScoreSeries:
    """Bin means (1 s by default) of the scored quantities over the record: what the plots, the
    JSON series and the Allan deviation use. Angles rad, rates rad/s; NaN in bins without a value.
    Per-method quantities take the method name (or ORACLE / RAW where noted)."""

    def __init__(self, t0_s: float, bin_s: float):
        self._bins = BinnedMeans(t0_s, bin_s, keep_max_abs=lambda key: isinstance(key, tuple) and key[0] == 'error')

    def add(self, rows: ScoredRows, errors: Mapping[str, np.ndarray], excesses: Mapping[str, np.ndarray],
            method_names: Sequence[str]) -> None:
        """One scored batch: `errors` per method and ORACLE, `excesses` per method (e0 removed)."""
        channels = {'truth_drift': rows.true_drift, 'outage': rows.outage.astype(float)}
        channels.update({('error', name): e for name, e in errors.items()})
        channels.update({('rate_error', name): r for name, r in rows.rate_error.items()})
        for name in method_names:
            channels[('excess', name)] = excesses[name]
            channels[('drift', name)] = rows.drift[name]
        self._bins.add(rows.t, channels)

    @property
    def bin_s(self) -> float:
        return self._bins.bin_s

    def centers_s(self) -> np.ndarray:
        """Bin centre times, s (the same clock as the samples)."""
        return self._bins.centers_s()

    def truth_drift(self) -> np.ndarray:
        """D_true, rad/s."""
        return self._bins.mean('truth_drift')

    def outage_fraction(self) -> np.ndarray:
        """Fraction of each bin's samples inside an outage span."""
        return self._bins.mean('outage')

    def error(self, name: str) -> np.ndarray:
        """Heading error e of a method or ORACLE, rad."""
        return self._bins.mean(('error', name))

    def error_max_abs(self, name: str) -> np.ndarray:
        """Per-sample max |e| in each bin of a method or ORACLE, rad (NaN: no sample)."""
        return self._bins.max_abs(('error', name))

    def excess(self, name: str) -> np.ndarray:
        """e - e_oracle of a method, rad."""
        return self._bins.mean(('excess', name))

    def drift(self, name: str) -> np.ndarray:
        """A method's drift estimate, rad/s."""
        return self._bins.mean(('drift', name))

    def rate_error(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(bin means, samples per bin) of the rate error of a method, RAW or ORACLE, rad/s."""
        return self._bins.mean(('rate_error', name)), self._bins.counts(('rate_error', name))


# ----------------------------------------------------------------------------------------------
# Results
# ----------------------------------------------------------------------------------------------
@dataclass
class MethodScore:
    """Everything scored for one method (or the oracle). Angles rad, rates rad/s."""
    name: str
    error: RunningStats = field(default_factory=RunningStats)             # e, whole record
    error_outage: RunningStats = field(default_factory=RunningStats)      # e inside outage spans
    excess: RunningStats = field(default_factory=RunningStats)            # e - e_oracle
    excess_outage: RunningStats = field(default_factory=RunningStats)
    bias_error: RunningStats = field(default_factory=RunningStats)        # D_hat - D_true, rad/s
    bias_error_outage: RunningStats = field(default_factory=RunningStats)
    reference_offset_rad: float = np.nan  # e0: mean raw error over the reference window
    coasting_in_outage: int = 0           # samples flagged coasting inside spans
    coasting_outside: int = 0             # ... outside spans (gate shut without interference)
    samples_in_outage: int = 0
    samples_outside: int = 0

    @property
    def coasting_fraction_in_outage(self) -> float:
        return self.coasting_in_outage / self.samples_in_outage if self.samples_in_outage else np.nan

    @property
    def coasting_fraction_outside(self) -> float:
        return self.coasting_outside / self.samples_outside if self.samples_outside else np.nan


@dataclass
class ScoreResult:
    method_names: list[str]
    scores: dict[str, MethodScore]        # methods and ORACLE
    spans: list[OutageSpan]
    series: ScoreSeries | None            # 1-s means of errors, excesses, drifts, rate errors
    allan: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (tau s, ADEV rad/s); incl. RAW, ORACLE
    t_start_s: float
    t_end_s: float
    samples_scored: int
    samples_unscored: int                 # IMU samples outside the truth's time span
    has_bias_truth: bool
    has_outage_truth: bool
    reference_window_s: float


# ----------------------------------------------------------------------------------------------
# The scorer
# ----------------------------------------------------------------------------------------------
class _TruthBuffer:
    """Tail of one truth stream: enough samples to interpolate at times not yet processed."""

    def __init__(self, width: int):
        self.t = np.empty(0)
        self.v = np.empty((0, width))

    def append(self, t: np.ndarray, v: np.ndarray) -> None:
        if t.size:
            self.t = np.concatenate([self.t, t])
            self.v = np.concatenate([self.v, v.reshape(t.size, -1)])

    @property
    def last_t(self) -> float:
        return self.t[-1] if self.t.size else -np.inf

    @property
    def first_t(self) -> float:
        return self.t[0] if self.t.size else np.inf

    def interp(self, t: np.ndarray, col: int) -> np.ndarray:
        """Linear interpolation; held constant beyond the ends."""
        return np.interp(t, self.t, self.v[:, col])

    def hold(self, t: np.ndarray, col: int) -> np.ndarray:
        """Latest sample at or before each t (NaN before the first)."""
        i = np.searchsorted(self.t, t, side='right') - 1
        out = np.full(t.shape, np.nan)
        out[i >= 0] = self.v[i[i >= 0], col]
        return out

    def trim(self, t_done: float) -> None:
        """Drop samples no longer needed once every time <= t_done has been processed."""
        keep = max(0, int(np.searchsorted(self.t, t_done, side='right')) - 1)
        if keep:
            self.t, self.v = self.t[keep:], self.v[keep:]


def _continue_angle(prev: float | None, wrapped: np.ndarray) -> np.ndarray:
    """Make a sequence of wrapped angles continuous, starting next to `prev` (or at wrapped[0])."""
    if wrapped.size == 0:
        return wrapped
    steps = wrap_angle(np.diff(wrapped)) if wrapped.size > 1 else np.empty(0)
    start = wrapped[0] if prev is None else prev + wrap_angle(wrapped[0] - prev)
    return start + np.concatenate([[0.0], np.cumsum(steps)])


@dataclass
class _ImuRows:
    """IMU samples and every method's output for them, waiting for truth (one row per sample)."""
    t: np.ndarray                     # (N,) s
    gyro_z: np.ndarray                # (N,) raw z gyro, rad/s
    heading: dict[str, np.ndarray]    # method name -> (N,) heading, rad
    drift: dict[str, np.ndarray]      # method name -> (N,) drift estimate, rad/s
    coasting: dict[str, np.ndarray]   # method name -> (N,) 1.0 where coasting, else 0.0
    sigma: dict[str, np.ndarray]      # method name -> (N,) published heading 1-sigma, rad (NaN: none)

    def __len__(self) -> int:
        return self.t.size

    def map(self, fn: Callable[[np.ndarray], np.ndarray]) -> '_ImuRows':
        """The same rows with `fn` applied to every array (a slice, a selection, a copy)."""
        def each(value):
            return {name: fn(v) for name, v in value.items()} if isinstance(value, dict) else fn(value)
        return _ImuRows(**{f.name: each(getattr(self, f.name)) for f in fields(self)})

    def followed_by(self, later: '_ImuRows') -> '_ImuRows':
        """These rows, then `later`'s."""
        def join(a, b):
            return ({name: np.concatenate([a[name], b[name]]) for name in a} if isinstance(a, dict)
                    else np.concatenate([a, b]))
        return _ImuRows(**{f.name: join(getattr(self, f.name), getattr(later, f.name)) for f in fields(self)})


class HeadingScorer:
    """Scores several heading methods against the truth streams of the same SensorChunks.

    Feed `add(chunk, {name: track})` in time order (one track row per `chunk.imu` sample, as the
    `HeadingMethod` protocol promises), then call `finish()` once.
    """

    def __init__(self, method_names: Sequence[str], *, reference_window_s: float = 60.0,
                 bin_s: float = 1.0, outage_truth: bool = True, outage_threshold_t: float = 0.0,
                 earth_rate_enu_rad_s=None):
        names = list(method_names)
        if len(set(names)) != len(names):
            raise ScoringError(f'method names must be unique: {names}')
        if ORACLE in names or RAW in names:
            raise ScoringError(f'"{ORACLE}" and "{RAW}" are reserved names')
        self.names = names
        self.reference_window_s = float(reference_window_s)
        self.bin_s = float(bin_s)
        self.use_outage_truth = bool(outage_truth)
        self.outage_threshold_t = float(outage_threshold_t)
        self.earth_rate_enu_rad_s = (None if earth_rate_enu_rad_s is None
                                     else np.asarray(earth_rate_enu_rad_s, dtype=float).reshape(3))

        # truth tails: odom columns = yaw (continuous), roll (continuous), pitch, rate_y, rate_z
        self._odom = _TruthBuffer(5)
        self._bias = _TruthBuffer(1)     # D_true z, rad/s
        self._dist = _TruthBuffer(1)     # |disturbance|, T
        self._joint = _TruthBuffer(1)    # turntable/wheel joint rate about sensor z, rad/s
        self._yaw_cont_prev: float | None = None
        self._roll_cont_prev: float | None = None
        self._expect_bias = self._expect_dist = self._expect_joint = None  # set by the first odom chunk

        # samples waiting for truth
        self._pending: _ImuRows | None = None

        # integration / continuity state
        self._oracle_prev: tuple[float, float, float] | None = None  # (t, rate, psi)
        self._e_prev: dict[str, float | None] = {n: None for n in names}

        self._window = ReferenceWindow(self.reference_window_s, names + [ORACLE])   # e0
        self.scores = {n: MethodScore(n) for n in names + [ORACLE]}
        self._outages = OutageSpans(ORACLE, names)
        self.spans: list[OutageSpan] = self._outages.spans
        self.series: ScoreSeries | None = None
        self._n_scored = 0
        self._n_unscored = 0
        self._t_last = np.nan
        self._finished = False

    # -- input ------------------------------------------------------------------------------
    def add(self, chunk: SensorChunk, tracks: Mapping[str, HeadingTrack]) -> None:
        if self._finished:
            raise ScoringError('add() after finish()')
        self._add_truth(chunk)
        imu = chunk.imu
        n = 0 if imu is None else imu.t.size
        for name in self.names:
            track = tracks.get(name)
            if track is None:
                raise ScoringError(f'no output from method "{name}"')
            if track.t.size != n:
                raise ScoringError(f'method "{name}" returned {track.t.size} rows for {n} IMU samples')
        if n:
            rows = _ImuRows(
                t=imu.t, gyro_z=imu.gyro[:, 2],
                heading={name: np.asarray(tracks[name].heading_rad, dtype=float) for name in self.names},
                drift={name: np.asarray(tracks[name].drift_rad_s, dtype=float) for name in self.names},
                coasting={name: np.asarray(tracks[name].coasting, dtype=float) for name in self.names},
                sigma={name: np.asarray(tracks[name].heading_sigma_rad, dtype=float) for name in self.names})
            self._pending = rows.map(np.copy) if self._pending is None else self._pending.followed_by(rows)
        self._process(final=False)

    def _add_truth(self, chunk: SensorChunk) -> None:
        odom = chunk.odom
        if odom is not None and odom.t.size:
            roll, pitch, yaw = euler_from_quat(odom.quat)
            # continuous yaw/roll so linear interpolation never crosses the +-pi seam
            yaw_c = _continue_angle(self._yaw_cont_prev, yaw)
            roll_c = _continue_angle(self._roll_cont_prev, roll)
            self._yaw_cont_prev, self._roll_cont_prev = float(yaw_c[-1]), float(roll_c[-1])
            self._odom.append(odom.t, np.column_stack([yaw_c, roll_c, pitch, odom.rate_body[:, 1],
                                                       odom.rate_body[:, 2]]))
            if self._expect_bias is None:
                self._expect_bias = chunk.gyro_bias is not None or self._bias.t.size > 0
                self._expect_dist = self.use_outage_truth and (
                    chunk.mag_disturbance is not None or self._dist.t.size > 0)
                self._expect_joint = chunk.joint is not None or self._joint.t.size > 0
        if chunk.gyro_bias is not None and chunk.gyro_bias.t.size:
            self._bias.append(chunk.gyro_bias.t, chunk.gyro_bias.vec[:, 2])
        if chunk.joint is not None and chunk.joint.t.size:
            self._joint.append(chunk.joint.t, chunk.joint.velocity)
        if self.use_outage_truth and chunk.mag_disturbance is not None and chunk.mag_disturbance.t.size:
            self._dist.append(chunk.mag_disturbance.t, np.linalg.norm(chunk.mag_disturbance.vec, axis=1))

    # -- alignment --------------------------------------------------------------------------
    def _process(self, final: bool) -> None:
        if self._pending is None:
            return
        t = self._pending.t
        if not self._odom.t.size:
            if final:
                raise ScoringError('no ground truth odometry (/ground_truth/odom) in the stream')
            if t[-1] - t[0] > _MAX_UNTRUTHED_S:
                raise ScoringError(f'no ground truth odometry within {_MAX_UNTRUTHED_S:.0f} s of IMU data')
            return
        horizon = np.inf if final else self._odom.last_t
        if not final and self._expect_bias:
            horizon = min(horizon, self._bias.last_t)
        if not final and self._expect_dist:
            horizon = min(horizon, self._dist.last_t)
        if not final and self._expect_joint:
            horizon = min(horizon, self._joint.last_t)
        n_ready = int(np.searchsorted(t, horizon, side='right'))
        if n_ready == 0:
            return
        batch = self._pending.map(lambda v: v[:n_ready])
        rest = self._pending.map(lambda v: v[n_ready:])
        self._pending = rest if len(rest) else None
        # samples outside the truth's time span cannot be scored (no extrapolation: a held yaw
        # would be wrong while turning)
        t_truth0, t_truth1 = self._odom.first_t, self._odom.last_t
        if self._expect_bias:
            t_truth0, t_truth1 = max(t_truth0, self._bias.first_t), min(t_truth1, self._bias.last_t)
        keep = (batch.t >= t_truth0) & (batch.t <= t_truth1)
        self._n_unscored += int(np.count_nonzero(~keep))
        if not keep.all():
            batch = batch.map(lambda v: v[keep])
        if len(batch):
            self._score_batch(batch)
            t_done = batch.t[-1]
            self._odom.trim(t_done)
            self._bias.trim(t_done)
            self._dist.trim(t_done)
            self._joint.trim(t_done)

    def _score_batch(self, batch: _ImuRows) -> None:
        t, gz = batch.t, batch.gyro_z
        if self._expect_joint and self._joint.t.size:
            gz = gz - self._joint.interp(t, 0)  # turntable spin about sensor z = body z
        yaw = self._odom.interp(t, 0)
        roll, pitch = self._odom.interp(t, 1), self._odom.interp(t, 2)
        rate_y, rate_z = self._odom.interp(t, 3), self._odom.interp(t, 4)
        d_true = self._bias.interp(t, 0) if self._expect_bias and self._bias.t.size else np.full(t.shape, np.nan)
        if self.earth_rate_enu_rad_s is not None:
            # the z gyro also senses the Earth rate projected on body z (third column of R_zyx)
            sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
            sy, cy = np.sin(yaw), np.cos(yaw)
            z_enu = np.column_stack([cy * cr * sp + sy * sr, sy * cr * sp - cy * sr, cr * cp])
            d_true = d_true + z_enu @ self.earth_rate_enu_rad_s
        if self._expect_dist and self._dist.t.size:
            outage = np.nan_to_num(self._dist.hold(t, 0), nan=0.0) > self.outage_threshold_t
        else:
            outage = np.zeros(t.shape, dtype=bool)

        # oracle: exact ZYX yaw rate from the drift-free z gyro (x/y coupling from the truth)
        cos_pitch = np.cos(pitch)
        cos_pitch = np.where(np.abs(cos_pitch) < 1e-6, np.copysign(1e-6, cos_pitch), cos_pitch)
        rate = (np.sin(roll) * rate_y + np.cos(roll) * (gz - d_true)) / cos_pitch
        if self._oracle_prev is None:
            t_prev, r_prev, psi_prev = t[0], rate[0], yaw[0]
        else:
            t_prev, r_prev, psi_prev = self._oracle_prev
        tt, rr = np.concatenate([[t_prev], t]), np.concatenate([[r_prev], rate])
        psi = psi_prev + np.cumsum(0.5 * (rr[1:] + rr[:-1]) * np.diff(tt))
        self._oracle_prev = (float(t[-1]), float(rate[-1]), float(psi[-1]))

        rows = ScoredRows(t=t, outage=outage, true_drift=d_true, error_raw={ORACLE: psi - yaw},
                           rate_error={RAW: gz - rate_z, ORACLE: gz - d_true - rate_z},
                           drift=dict(batch.drift), coasting={}, sigma=dict(batch.sigma))
        for name in self.names:
            diff = wrap_angle(batch.heading[name] - yaw)
            e = np.full(t.shape, np.nan)
            ok = np.isfinite(diff)
            if ok.any():
                e[ok] = _continue_angle(self._e_prev[name], diff[ok])
                self._e_prev[name] = float(e[ok][-1])
            rows.error_raw[name] = e
            rows.coasting[name] = batch.coasting[name] > 0.5
            rows.rate_error[name] = gz - batch.drift[name] - rate_z
        self._t_last = float(t[-1])
        self._reference(rows)

    # -- reference window (e0) --------------------------------------------------------------
    def _reference(self, rows: ScoredRows) -> None:
        ready = self._window.add(rows)
        if self.series is None:
            self.series = ScoreSeries(self._window.t_first, self.bin_s)
        for scored in ready:
            self._accumulate(scored)

    # -- statistics -------------------------------------------------------------------------
    def _accumulate(self, rows: ScoredRows) -> None:
        t, outage = rows.t, rows.outage
        self._n_scored += t.size
        errors, excesses = {}, {}
        for name in [ORACLE] + self.names:
            e0 = self._window.offset(name, rows.error_raw[name])
            self.scores[name].reference_offset_rad = e0
            errors[name] = rows.error_raw[name] - e0
            excesses[name] = errors[name] - errors[ORACLE]
        d_true = rows.true_drift
        n_out = int(np.count_nonzero(outage))
        for name in [ORACLE] + self.names:
            s, e, x = self.scores[name], errors[name], excesses[name]
            s.error.add(e)
            s.error_outage.add(e[outage])
            s.excess.add(x)
            s.excess_outage.add(x[outage])
            if name != ORACLE:
                be = rows.drift[name] - d_true
                s.bias_error.add(be)
                s.bias_error_outage.add(be[outage])
                coast = rows.coasting[name]
                s.coasting_in_outage += int(np.count_nonzero(coast & outage))
                s.coasting_outside += int(np.count_nonzero(coast & ~outage))
            s.samples_in_outage += n_out
            s.samples_outside += t.size - n_out
        self._outages.add(rows, errors, excesses)
        self.series.add(rows, errors, excesses, self.names)

    # -- output -----------------------------------------------------------------------------
    def finish(self) -> ScoreResult:
        if not self._finished:
            self._process(final=True)
            for scored in self._window.close():
                self._accumulate(scored)
            self._finished = True
        if self._window.t_first is None:
            raise ScoringError('no IMU sample could be scored (no IMU data inside the truth time span)')
        allan = {name: allan_from_bin_means(*self.series.rate_error(name), self.bin_s)
                 for name in [RAW, ORACLE] + self.names}
        return ScoreResult(
            method_names=list(self.names), scores=self.scores, spans=self.spans, series=self.series,
            allan=allan, t_start_s=self._window.t_first, t_end_s=self._t_last,
            samples_scored=self._n_scored, samples_unscored=self._n_unscored,
            has_bias_truth=bool(self._expect_bias), has_outage_truth=bool(self._expect_dist),
            reference_window_s=self.reference_window_s)
