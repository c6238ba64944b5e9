"""Is the compass trustworthy right now? Independent named tests, hysteresis and a hold-off.

Each test closes the gate for a named reason (bit i of the reason mask is REASONS[i]):
- `field_norm`: |B| deviates from its reference by more than `field_norm_tol` (relative). Catches
  most added fields. The reference is |B| = n0 + n1 (T - T_ref), fitted by recursive least squares
  (memory `reference_memory_s`) while the gate is open: magnetoresistive sensitivity drifts by
  ~0.3 %/degC, 10 % over a 35 degC ramp, and during an outage the reference follows the live
  temperature.
- `dip_angle`: the inclination deviates from its reference (same memory) by more than `dip_tol_deg`.
  Both references are heading-dependent on a vehicle (hard and soft iron), so after turning (rate
  above `turn_rate_deg_s`, whether or not `turn_rate` closes the gate) their level is re-learned
  over `reference_relearn_s` and the two tests rest meanwhile. A turn, not the accumulated gyro
  heading: a coasting gyro drifts, and a reference re-learned inside a disturbance is worthless.
  The first `reference_s` (the estimator's still period) are such a learning period.
- `heading_rate_mismatch`: the compass heading moves while the gyro heading does not (the paper's
  test; the gyro is blind to magnetic fields). r = psi_gyro - psi_compass, averaged over
  `mismatch_smooth_s`, moves at the residual drift rate, which may be large while the drift model
  is still learning; interference instead bends r. So while open the test is the second difference
  |r(t) - 2 r(t - W/2) + r(t - W)| over W = `mismatch_window_s`, blind to any steady drift. Once the
  gate is shut for any reason other than a turn, the test passes again only when r has been stable
  (at most a straight line, i.e. a residual drift) over `mismatch_settle_s` AND either agrees with
  its value at the last open instant, within an allowance growing with angle random walk and
  drift uncertainty, or the gate has been shut for `mismatch_max_s` and r has been stable for the
  whole last `mismatch_settle_s` (a disturbance that breathes is never accepted), or r has been a
  drift line (below). So a disturbance that only rotates the field keeps the gate shut until the
  compass comes back to where the gyro says it should be, and a coasting error larger than the
  allowance cannot lock the gate for ever.
  A drift line: over the last `mismatch_line_s` r has stayed within `mismatch_line_rms_deg` (rms) of
  a straight line whose slope is beyond `mismatch_sigma` x the drift uncertainty and moves r by
  more than the bend threshold over the window, with r stable over `mismatch_settle_s` the whole
  time (a disturbance's onset or its breathing starts the line again). That is the drift estimate
  being wrong (a model extrapolating past its calibration ran 0.17 deg/s off on a simulated
  family-B ramp, and the test held the clean compass out for 600 s: 110 deg of error), not a
  field: the simulated disturbances breathe (periods 60-150 s) and a real one moves with the
  vehicle, neither keeps a constant rate for minutes. A steady offset (a disturbance that holds
  still) has no slope and stays shut. The heading filter refuses a steady disagreement the same
  way for `reject_max_s` before accepting it.
- `turn_rate`: turning faster than `turn_rate_deg_s` (heading-dependent compass deviation means
  only straight segments are comparable; switch off with `turn_rate_enabled=False` for turntables).
  A turn restarts the mismatch history (the deviation at the new heading is different).
- `accel_norm`: the accelerometer's departure from gravity, | |f| - g |, above
  `accel_norm_tol_m_s2`: roll/pitch from gravity, hence the tilt
  compensation, are wrong.
Each test closes at its threshold and reopens below `hysteresis` x threshold; the gate reopens only
after `holdoff_s` with no active test (reported as the reason `holdoff` meanwhile).

Inputs are per observation (single compass samples, or short block means). The state machine is a
loop over observations: it is sequential by nature.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..angles import wrap_angle
from .reasons import GATE_REASONS, REASON_BIT, reason_names
from .temperature_line import ShutFit, TemperatureLine

REASONS = GATE_REASONS
BIT = REASON_BIT


@dataclass(frozen=True)
class GateConfig:
    """Thresholds of the magnetic gate. Angles in degrees where the name says so."""
    reference_memory_s: float = 600.0       # memory of the references while open
    reference_relearn_s: float = 3.0        # after a turn, re-learn the reference levels this long, s
    norm_tc_prior: float = 0.005            # prior 1-sigma of the relative change per degC of |B| and of |f| at rest
    dip_tc_prior_deg: float = 0.1           # prior 1-sigma of the dip's change per degC, deg
    field_norm_tol: float = 0.02            # relative |B| deviation that closes the gate
    dip_tol_deg: float = 1.0                # dip deviation that closes the gate, deg
    mismatch_enabled: bool = True           # the compass-vs-gyro heading-rate test
    mismatch_deg: float = 1.0               # compass-vs-gyro disagreement (bend of r)
    mismatch_window_s: float = 10.0         # window of its second difference, s
    mismatch_smooth_s: float = 1.0          # moving average of r before testing
    mismatch_sigma: float = 2.0             # allowance: mismatch_deg + k*sqrt(ARW^2 t + (drift t)^2)
    mismatch_noise_sigma: float = 4.0       # the bend threshold is at least this many sigma of the
                                            # bend's own noise (compass noise after smoothing, ARW)
    mismatch_drift_deg_s: float = 0.005     # drift-estimate uncertainty allowed while shut (floor)
    mismatch_settle_s: float = 30.0         # r must be this long stable before reopening
    mismatch_max_s: float = 600.0           # after this, a stable compass is accepted as it is
    mismatch_line_s: float = 120.0          # r a straight line this long, drifting: accepted, s (0 = off)
    mismatch_line_rms_deg: float = 0.5      # rms of r about that line that still counts as straight, deg
    turn_rate_enabled: bool = True          # close while turning (vehicles); off for turntables
    turn_rate_deg_s: float = 2.0            # turning faster than this, deg/s
    turn_window_s: float = 1.0              # turn rate measured over this window, s
    accel_norm_tol_m_s2: float = 0.5        # |f| off its value at rest by this closes the gate, m/s^2
    hysteresis: float = 0.7                 # a test reopens below this fraction of its threshold
    holdoff_s: float = 5.0                  # reopen only after this long with no active test, s


@dataclass(frozen=True)
class GateResult:
    open: np.ndarray     # (M,) bool
    reasons: np.ndarray  # (M,) int bit mask over REASONS

    def names(self, i: int) -> list[str]:
        return reason_names(self.reasons[i])


def _sqrt(v: float) -> float:
    """np.sqrt for one Python float (the same correctly rounded value, NaN below 0), ~20x cheaper."""
    return math.sqrt(v) if v >= 0.0 else math.nan


def _push(trail: '_Trail', t: float, v: float) -> float:
    """Append (t, v) to a trail, drop what fell out of its window, return its oldest value. A function,
    not a method: the gate calls it five times per observation."""
    q = trail.q
    q.append((t, v))
    cut = t - trail.window_s
    while len(q) > 1 and q[1][0] <= cut:
        q.popleft()
    return q[0][1]


class _Trail:
    """Values over a trailing time window (`_push` adds one and returns the value at its start)."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self.q: deque = deque()

    def span(self) -> float:
        return self.q[-1][0] - self.q[0][0] if self.q else 0.0


class _LineTrail(_Trail):
    """A trail that keeps the sums of its least-squares straight line (`line`: O(1) per observation,
    for a window of a thousand). Sums about the first entry since the last rebuild, rebuilt once that
    is 10 windows old, so they keep their precision through a shut of hours."""

    def __init__(self, window_s: float):
        super().__init__(window_s)
        self.rebuild()

    def rebuild(self) -> None:
        """Sums afresh from the entries (after a clear, or the values were re-expressed)."""
        q = self.q
        self._base = q[0] if q else None
        self._sums = [0.0] * 6     # n, u, u^2, v, u v, v^2 with u, v = t, r about the base
        for t, v in q:
            self._add(t, v, 1.0)

    def clear(self) -> None:
        self.q.clear()
        self.rebuild()

    def _add(self, t: float, v: float, w: float) -> None:
        u, v = t - self._base[0], v - self._base[1]
        a = self._sums
        a[0] += w
        a[1] += w * u
        a[2] += w * u * u
        a[3] += w * v
        a[4] += w * u * v
        a[5] += w * v * v

    def push(self, t: float, v: float) -> None:
        q = self.q
        if not q:
            self._base = (t, v)
        q.append((t, v))
        self._add(t, v, 1.0)
        cut = t - self.window_s
        while len(q) > 1 and q[1][0] <= cut:
            self._add(*q.popleft(), -1.0)
        if t - self._base[0] > 10.0 * self.window_s:
            self.rebuild()

    def line(self) -> tuple[float, float]:
        """Least-squares straight line through the trail: (slope per s, rms of the residuals)."""
        n, su, suu, sv, suv, svv = self._sums
        var_u = suu - su * su / n
        cov = suv - su * sv / n
        slope = cov / var_u if var_u > 0 else 0.0
        rss = svv - sv * sv / n - slope * cov
        return slope, _sqrt(max(rss, 0.0) / n)


class GateReferences:
    """What the field and the accelerometer read when they can be trusted, each a line in
    temperature (temperature_line.py): |B| (T), the dip (rad) and the accelerometer's norm at rest
    |f| (m/s^2). Learned as plain means over a learning period (the still period at the start; the
    field's levels again after every turn, keeping their slopes), then by RLS (memory `memory_s`)
    while the gate is open. While a test is shut, a `ShutFit` per quantity may show the excursion
    was the sensor's temperature response (`refit`)."""

    NORM_NOISE = 2e-3           # block-mean |B| and |f| noise, relative to the level (RLS weights)
    DIP_NOISE_RAD = math.radians(0.2)
    SHUT_FIT_WINDOW_S = 60.0    # a shut fit judges the last minute of the shut
    MAX_FORGET_STEP_S = 10.0    # forgetting counts observed time: a compass silent for an hour
                                # does not erase what was learned before it
    NOISE_SIGMAS = 4.0          # a test fires at its tolerance or at this many sigmas of the
                                # observation's own white noise, whichever is larger

    def __init__(self, memory_s: float, norm_tc_prior: float, dip_tc_prior_rad: float):
        self.memory_s = memory_s
        self.norm_tc_prior = norm_tc_prior
        self.dip_tc_prior_rad = dip_tc_prior_rad
        self.lines: dict[str, TemperatureLine] = {}
        self.fits = {name: ShutFit(self.SHUT_FIT_WINDOW_S) for name in ('field_norm', 'dip_angle', 'accel_norm')}
        self.refits = dict.fromkeys(self.fits, 0)
        self.noise2 = dict.fromkeys(self.fits, 0.0)   # white-noise variance of each observation
        self._last_obs: tuple | None = None    # the previous observation (successive differences)
        self._n_noise = 0
        self.temp_open = math.nan                # the temperature at the latest open observation, degC
        self.learn_until: float | None = None  # (re)learning until then, s
        self.learn_accel = False               # this learning period also sets the rest |f|
        self.started = False
        self._sums = [0, 0.0, 0.0, 0.0, 0.0]   # count, sum |B|, sum dip, sum |f|, sum T of the learning period
        self._n_temp = 0
        self._decay_cache: dict = {}

    @property
    def norm(self) -> float | None:
        line = self.lines.get('field_norm')
        return None if line is None else line.level

    @property
    def dip(self) -> float | None:
        line = self.lines.get('dip_angle')
        return None if line is None else line.level

    def at(self, name: str, temperature_c: float) -> float:
        """The reference of `field_norm` (T), `dip_angle` (rad) or `accel_norm` (m/s^2) at a
        temperature (degC); NaN before one exists."""
        line = self.lines.get(name)
        return math.nan if line is None else line.at(temperature_c)

    def slopes(self) -> dict[str, float]:
        """The learned temperature slopes, per degC, in each reference's unit."""
        return {name: line.slope for name, line in self.lines.items()}

    def noise_sigmas(self) -> dict[str, float]:
        """Each observation's measured white noise, 1 sigma, in its reference's unit."""
        return {name: math.sqrt(v) for name, v in self.noise2.items()}

    def start_learning(self, t_s: float, duration_s: float, accel: bool = False) -> None:
        self.learn_until = t_s + duration_s
        self.learn_accel = accel
        self._sums = [0, 0.0, 0.0, 0.0, 0.0]
        self._n_temp = 0
        self.started = True
        for fit in self.fits.values():
            fit.clear()

    def _decay(self, dt_s: float) -> float:
        """exp(-dt / memory), cached: block observations come at a few fixed spacings."""
        key = (dt_s, self.memory_s)
        lam = self._decay_cache.get(key)
        if lam is None:
            if len(self._decay_cache) > 64:
                self._decay_cache.clear()
            lam = self._decay_cache[key] = float(np.exp(-max(dt_s, 0.0) / self.memory_s))
        return lam

    def _line(self, name: str, level: float) -> TemperatureLine:
        line = self.lines.get(name)
        if line is None:
            if name == 'dip_angle':
                line = TemperatureLine(self.DIP_NOISE_RAD, self.dip_tc_prior_rad)
            else:
                line = TemperatureLine(self.NORM_NOISE * abs(level), self.norm_tc_prior * abs(level))
            self.lines[name] = line
        return line

    def tolerance(self, name: str, tolerance: float) -> float:
        """A test's threshold: its tolerance, or `NOISE_SIGMAS` sigmas of the observation's white
        noise if larger (a 1 Hz tag's dip scatters 0.4 deg per sample: a 1 deg test fired on it)."""
        return max(tolerance, self.NOISE_SIGMAS * math.sqrt(self.noise2[name]))

    def _noise(self, obs: tuple, lam: float, learning: bool) -> None:
        """White-noise variance from successive differences (half their mean square), averaged
        over the learning period, then with forgetting `lam`."""
        last, self._last_obs = self._last_obs, obs
        if last is None:
            return
        self._n_noise += 1
        w = 1.0 / self._n_noise if learning else 1.0 - lam
        for name, y, y0 in zip(('field_norm', 'dip_angle', 'accel_norm'), obs, last):
            d2 = 0.5 * (y - y0) ** 2
            if d2 == d2:
                self.noise2[name] += w * (d2 - self.noise2[name])

    def observe(self, t_s, norm, dip, accel, temp, dt_obs, is_open) -> None:
        """Reference bookkeeping for one observation."""
        if self.learn_until is not None or is_open:
            self._noise((norm, dip, accel), self._decay(dt_obs), self.learn_until is not None)
        else:
            self._last_obs = None   # no differences across a shut
        if self.learn_until is not None:
            acc = self._sums
            acc[0] += 1
            acc[1] += norm
            acc[2] += dip
            acc[3] += accel
            if temp == temp:
                acc[4] += temp
                self._n_temp += 1
            if t_s >= self.learn_until:
                t_mean = acc[4] / self._n_temp if self._n_temp else math.nan
                names = ('field_norm', 'dip_angle') + (('accel_norm',) if self.learn_accel else ())
                for name, total in zip(names, acc[1:4]):
                    mean = total / acc[0]
                    if mean == mean:
                        self._line(name, mean).set_level(mean, t_mean)
                self.learn_until = None
            return
        if is_open:
            self.temp_open = temp
            lam = self._decay(min(dt_obs, self.MAX_FORGET_STEP_S))
            for name, y in (('field_norm', norm), ('dip_angle', dip), ('accel_norm', accel)):
                line = self.lines.get(name)
                if line is not None and y == y:
                    line.step(y, temp, lam)

    def shut(self, name: str, active: bool, t_s: float, y: float, temp: float, tolerance: float) -> bool:
        """While test `name` is active: one observation into its shut fit; True if the fit shows
        the excursion is the sensor's temperature response (the reference has taken the line)."""
        fit = self.fits[name]
        if not active:
            if fit.anchor is not None:
                fit.clear()
            return False
        line = self.lines.get(name)
        if line is None or not temp == temp:
            return False
        if fit.anchor is None:   # the reference was right where the gate last trusted the sensors
            t_a = self.temp_open if self.temp_open == self.temp_open else temp
            fit.start(t_a, line.at(t_a))
        fit.add(t_s, y, temp)
        slope = fit.explains(tolerance, line.slope_prior, math.sqrt(self.noise2[name]))
        if slope is None:
            return False
        line.set_line(fit.anchor[1], slope, fit.anchor[0], line.noise ** 2, line.slope_prior ** 2)
        self.refits[name] += 1
        fit.clear()
        return True


class MagneticGate:
    """Streaming compass gate; `update` takes observations in time order. `arw_rad_sqrt_s` (the
    gyro's angle random walk) and `reference_s` (the still period, when the references are first
    learned) are the estimator's values, passed once, not settings of the gate."""

    def __init__(self, config: GateConfig = GateConfig(), arw_rad_sqrt_s: float = np.radians(0.04),
                 reference_s: float = 30.0):
        cfg = self.cfg = config
        self.arw_rad_sqrt_s = float(arw_rad_sqrt_s)
        self.reference_s = float(reference_s)
        self.reference = GateReferences(cfg.reference_memory_s, cfg.norm_tc_prior, math.radians(cfg.dip_tc_prior_deg))
        # state machine
        self._active = {name: False for name in REASONS[:-1]}
        self._t_last_active = -np.inf
        self._open = True
        self._turning = False
        self._t_prev: float | None = None
        # mismatch and turn histories
        self._smooth = _Trail(cfg.mismatch_smooth_s)
        self._smooth_sum = 0.0
        self._smooth_var: deque = deque()      # compass variance of each entry of _smooth
        self._smooth_var_sum = 0.0
        self._win = _Trail(cfg.mismatch_window_s)
        self._win_half = _Trail(0.5 * cfg.mismatch_window_s)
        self._settle = _Trail(cfg.mismatch_settle_s)
        self._settle_half = _Trail(0.5 * cfg.mismatch_settle_s)
        self._line = _LineTrail(cfg.mismatch_line_s)   # r since the shut and since it was last unstable
        self._turn = _Trail(cfg.turn_window_s)
        self._r_last = None                    # last unwrapped r (continuity across calls)
        self._frozen: tuple | None = None      # (t, r) at the last open instant
        self._stable_since: float | None = None
        self._line_told = False                # this shut's drift line was reported
        self._drift_lines: list = []           # (t s, heading variance rad^2) not yet taken
        self.n_drift_lines = 0

    def take_drift_lines(self) -> list[tuple[float, float]]:
        """Drift lines accepted since the last call, as (t s, variance rad^2): the heading the gyro
        carried through the shut is that far off, so the heading filter must take the compass as it
        is (its innovation test would refuse it for `reject_max_s` more)."""
        lines, self._drift_lines = self._drift_lines, []
        return lines

    def set_config(self, config: GateConfig) -> None:
        """Change thresholds at run time: everything derived from them follows (the trailing
        windows take their new lengths; the learned references are kept)."""
        self.cfg = config
        self.reference.memory_s = config.reference_memory_s
        self.reference.norm_tc_prior = config.norm_tc_prior
        self.reference.dip_tc_prior_rad = math.radians(config.dip_tc_prior_deg)
        for trail, window_s in ((self._smooth, config.mismatch_smooth_s), (self._win, config.mismatch_window_s),
                                (self._win_half, 0.5 * config.mismatch_window_s),
                                (self._settle, config.mismatch_settle_s),
                                (self._settle_half, 0.5 * config.mismatch_settle_s),
                                (self._line, config.mismatch_line_s), (self._turn, config.turn_window_s)):
            trail.window_s = window_s

    # -- references (read-only views for diagnostics) -------------------------------------------
    @property
    def ref_norm(self) -> float | None:
        return self.reference.norm

    @property
    def ref_dip(self) -> float | None:
        return self.reference.dip

    def reference_norm(self, temperature_c: float) -> float:
        """Expected |B| (T) at a temperature (degC); NaN before a reference exists."""
        return self.reference.at('field_norm', temperature_c)

    # -- mismatch helpers -----------------------------------------------------------------------
    def reset_mismatch(self) -> None:
        """Forget compass-vs-gyro history (after a time gap: the heading relation is unknown)."""
        self._clear_r()
        self._turn.q.clear()
        self._frozen = None
        self._r_last = None

    def rebase(self, delta_rate_rad_s: float, t_ref_s: float) -> None:
        """The drift estimate changed by `delta_rate_rad_s` at `t_ref_s`: re-express the gyro
        heading history as if the new estimate had always been in force (continuous at t_ref_s).
        Otherwise the estimator's own correction bends r like interference does, and after a long
        coast the correction needed to catch up would keep the gate shut for ever."""
        d = float(delta_rate_rad_s)
        if d == 0.0 or not np.isfinite(d):
            return

        def shift(q: deque) -> deque:
            return deque((t, v + d * (t_ref_s - t)) for t, v in q)
        for trail in (self._smooth, self._win, self._win_half, self._settle, self._settle_half, self._line,
                      self._turn):
            trail.q = shift(trail.q)
        self._line.rebuild()
        self._smooth_sum = sum(v for _, v in self._smooth.q)
        if self._frozen is not None:
            self._frozen = shift(deque([self._frozen]))[0]
        if self._r_last is not None and self._t_prev is not None:
            self._r_last += d * (t_ref_s - self._t_prev)

    def _clear_r(self) -> None:
        for trail in (self._smooth, self._win, self._win_half, self._settle, self._settle_half):
            trail.q.clear()
        self._line.clear()
        self._smooth_sum = 0.0
        self._smooth_var.clear()
        self._smooth_var_sum = 0.0

    def _bend_threshold(self, thr: float, var_smooth: float, arw2: float) -> float:
        """`mismatch_deg`, raised to `mismatch_noise_sigma` sigma of the bend's noise: three smoothed
        compass values (weights 1, -2, 1) and the angle random walk over the window. A 5 Hz compass
        averages few samples per second, and a fixed 1 deg would then fire on noise."""
        noise = _sqrt(6.0 * var_smooth + arw2 * self.cfg.mismatch_window_s)
        return max(thr, self.cfg.mismatch_noise_sigma * noise)

    def _allow(self, age_s: float, thr: float, arw2: float, drift: float) -> float:
        """Disagreement explained by angle random walk and drift uncertainty over age_s (k sigma)."""
        return thr + self.cfg.mismatch_sigma * _sqrt(arw2 * age_s + (drift * age_s) ** 2)

    def _mismatch(self, t_now: float, r_now: float, thr: float, arw2: float, drift: float, var_i: float) -> float:
        """Mismatch test value as a fraction of its threshold (see the module docstring). Called per
        observation: the trails are pushed inline (`_push`), not through methods."""
        cfg = self.cfg
        # moving average of r over `mismatch_smooth_s` and its variance from compass noise
        q, qv = self._smooth.q, self._smooth_var
        q.append((t_now, r_now))
        qv.append(var_i)
        self._smooth_sum += r_now
        self._smooth_var_sum += var_i
        cut = t_now - cfg.mismatch_smooth_s
        while len(q) > 1 and q[0][0] <= cut:
            self._smooth_sum -= q.popleft()[1]
            self._smooth_var_sum -= qv.popleft()
        n = len(q)
        r_now, var_smooth = self._smooth_sum / n, max(self._smooth_var_sum, 0.0) / n ** 2
        thr = self._bend_threshold(thr, var_smooth, arw2)
        win = self._win
        bend = abs(r_now - 2.0 * _push(self._win_half, t_now, r_now) + _push(win, t_now, r_now))
        if win.q[-1][0] - win.q[0][0] < 0.9 * cfg.mismatch_window_s:
            bend = 0.0  # not yet a second difference: a residual-drift slope would read as a bend
        bend_settle = abs(r_now - 2.0 * _push(self._settle_half, t_now, r_now) + _push(self._settle, t_now, r_now))
        if self._open or self._frozen is None:
            return bend / thr
        t_f, r_f = self._frozen
        age = t_now - t_f
        stable = self._settle.span() >= 0.9 * cfg.mismatch_settle_s and \
            bend_settle <= self._allow(cfg.mismatch_settle_s, thr, arw2, 0.0)
        consistent = abs(r_now - r_f) <= self._allow(age, thr, arw2, drift)
        if not stable:
            self._stable_since = None
            self._line.clear()   # an onset or a breathing bend would tilt the line: start it again
        elif self._stable_since is None:
            self._stable_since = t_now
        self._line.push(t_now, r_now)
        settled = stable and t_now - self._stable_since >= cfg.mismatch_settle_s
        if stable and (consistent or (age > cfg.mismatch_max_s and settled)):
            return 0.0
        slope = self._drift_line(thr, drift, var_smooth) if stable else None
        if slope is None:
            return 2.0
        if not self._line_told:
            self._line_told = True
            self.n_drift_lines += 1
            self._drift_lines.append((t_now, (r_now - r_f) ** 2 + (slope * age) ** 2))
        return 0.0

    def _drift_line(self, thr: float, drift: float, var_smooth: float) -> float | None:
        """The slope (rad/s) if r has been a straight line over `mismatch_line_s` whose slope the drift
        uncertainty does not explain: the drift estimate is wrong, not the field (module docstring)."""
        cfg, line = self.cfg, self._line
        if cfg.mismatch_line_s <= 0 or line.span() < 0.9 * cfg.mismatch_line_s:
            return None
        slope, rms = line.line()
        steady = rms <= max(math.radians(cfg.mismatch_line_rms_deg), 2.0 * _sqrt(var_smooth))
        drifting = abs(slope) > cfg.mismatch_sigma * drift and abs(slope) * line.span() > thr
        return slope if steady and drifting else None

    def _freeze(self) -> None:
        """At closing: remember r at the last trusted instant (the mismatch window's start; the
        last window may already hold the onset)."""
        w = self._win.q
        self._frozen = (w[0][0], w[0][1]) if w else None
        self._stable_since = None
        self._line_told = False
        self._line.clear()   # the line is judged on the shut alone

    @staticmethod
    def _field_test(ref: GateReferences, name: str, active: bool, t_s: float, y: float, temp: float,
                    tolerance: float, hyst: float) -> bool:
        """One reference test with hysteresis; while it fires, the shut fit may find the excursion is
        the sensor's temperature response, and the test is judged again on the reference it took."""
        tolerance = ref.tolerance(name, tolerance)
        x = abs(y - ref.at(name, temp)) / tolerance
        now = x > (hyst if active else 1.0)
        if now and ref.shut(name, True, t_s, y, temp, tolerance):
            now = abs(y - ref.at(name, temp)) / tolerance > hyst
        elif not now:
            ref.shut(name, False, t_s, y, temp, tolerance)
        return now

    # -- update -------------------------------------------------------------------------------
    def update(self, t, field_norm_t, dip_rad, heading_compass_rad, heading_gyro_rad,
               accel_m_s2, temperature_c=None, drift_sigma_rad_s: float = 0.0,
               compass_var_rad2=0.0) -> GateResult:
        """Observations (M,): time s, |B| T, dip rad, compass heading rad (wrapped), gyro heading
        rad (continuous, drift-compensated), the accelerometer's norm |f| m/s^2 (judged against its
        value at rest, learned with the field's references), temperature degC (optional).
        `drift_sigma_rad_s`: current 1-sigma of the drift estimate (widens the mismatch allowance
        while shut; the config's mismatch_drift_deg_s is the floor). `compass_var_rad2`: variance
        of each compass heading observation, rad^2 (scalar or (M,)), for the mismatch threshold."""
        cfg = self.cfg
        t = np.asarray(t, dtype=float).reshape(-1)
        m = t.size
        if m == 0:
            return GateResult(np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64))
        psi_g = np.asarray(heading_gyro_rad, dtype=float).reshape(-1)
        temp = np.full(m, np.nan) if temperature_c is None else \
            np.asarray(temperature_c, dtype=float).reshape(-1)
        # r = psi_g - psi_c, continuous across calls
        r_wrapped = wrap_angle(psi_g - np.asarray(heading_compass_rad, dtype=float).reshape(-1))
        prev = r_wrapped[0] if self._r_last is None else self._r_last
        r = prev + np.cumsum(wrap_angle(np.diff(np.concatenate(([prev], r_wrapped)))))
        self._r_last = float(r[-1])
        accel_tol = cfg.accel_norm_tol_m_s2
        # Python floats for the per-observation loop (the same values as numpy scalars, cheaper)
        thr = float(np.radians(cfg.mismatch_deg))
        arw2 = self.arw_rad_sqrt_s ** 2
        drift = float(max(np.radians(cfg.mismatch_drift_deg_s), float(drift_sigma_rad_s)))
        turn_thr = float(np.radians(cfg.turn_rate_deg_s))
        dip_thr = float(np.radians(cfg.dip_tol_deg))
        hyst = cfg.hysteresis
        act = self._active
        lists = (t.tolist(), r.tolist(), psi_g.tolist(), np.asarray(field_norm_t, dtype=float).tolist(),
                 np.asarray(dip_rad, dtype=float).tolist(), temp.tolist(),
                 np.broadcast_to(np.asarray(accel_m_s2, dtype=float), (m,)).tolist(),
                 np.broadcast_to(np.asarray(compass_var_rad2, dtype=float), (m,)).tolist())
        is_open, reasons = [], []
        # the tests' states as locals for the loop (written back below); bits as in REASON_BIT
        a_turn, a_norm, a_dip = act['turn_rate'], act['field_norm'], act['dip_angle']
        a_accel, a_mis = act['accel_norm'], act['heading_rate_mismatch']
        b_turn, b_norm, b_dip, b_accel, b_mis, b_hold = (BIT[k] for k in (
            'turn_rate', 'field_norm', 'dip_angle', 'accel_norm', 'heading_rate_mismatch', 'holdoff'))
        turn_enabled, mismatch_enabled, holdoff_s = cfg.turn_rate_enabled, cfg.mismatch_enabled, cfg.holdoff_s
        norm_tol, relearn_s = cfg.field_norm_tol, cfg.reference_relearn_s
        ref = self.reference
        for t_now, r_now, psi_g_now, norm_now, dip_now, temp_now, accel_now, var_now in zip(*lists):
            dt_obs = t_now - self._t_prev if self._t_prev is not None else 0.0
            self._t_prev = t_now
            g_old = _push(self._turn, t_now, psi_g_now)
            turn_span = self._turn.span()
            turn_x = abs(psi_g_now - g_old) / turn_span / turn_thr if turn_span > 0 else 0.0
            turning = turn_x > (hyst if self._turning else 1.0)
            self._turning = turning
            a_turn = turn_enabled and turning
            # reference levels: learned at the start (with the rest |f|) and again after every turn
            if not ref.started:
                ref.start_learning(t_now, self.reference_s, accel=True)
            elif turning:
                ref.start_learning(t_now, relearn_s)
            if ref.learn_until is not None or not ref.at('field_norm', temp_now) > 0.0:   # no usable reference (yet)
                a_norm = a_dip = False
            else:
                a_norm = self._field_test(ref, 'field_norm', a_norm, t_now, norm_now, temp_now,
                                          norm_tol * ref.at('field_norm', temp_now), hyst)
                a_dip = self._field_test(ref, 'dip_angle', a_dip, t_now, dip_now, temp_now, dip_thr, hyst)
            if not ref.at('accel_norm', temp_now) > 0.0:   # no rest |f| yet
                a_accel = False
            else:
                a_accel = self._field_test(ref, 'accel_norm', a_accel, t_now, accel_now, temp_now, accel_tol, hyst)
            if a_turn:
                self._clear_r()
                self._frozen = None
                mismatch_x = 0.0
            else:
                mismatch_x = self._mismatch(t_now, r_now, thr, arw2, drift, var_now) if mismatch_enabled else 0.0
            a_mis = mismatch_x > (hyst if a_mis else 1.0)
            mask = (b_turn if a_turn else 0) | (b_norm if a_norm else 0) | (b_dip if a_dip else 0) | \
                (b_accel if a_accel else 0) | (b_mis if a_mis else 0)
            if mask:
                self._t_last_active = t_now
            elif t_now - self._t_last_active < holdoff_s:
                mask = b_hold
            now_open = mask == 0
            if self._open and not now_open:
                if a_turn:
                    self._frozen = None
                else:
                    self._freeze()
            elif now_open and not self._open:
                self._frozen = None
            self._open = now_open
            ref.observe(t_now, norm_now, dip_now, accel_now, temp_now, dt_obs, now_open)
            is_open.append(now_open)
            reasons.append(mask)
        act.update(turn_rate=a_turn, field_norm=a_norm, dip_angle=a_dip, accel_norm=a_accel,
                   heading_rate_mismatch=a_mis)
        return GateResult(np.array(is_open, dtype=bool), np.array(reasons, dtype=np.int64))
