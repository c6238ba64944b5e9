"""Is the compass trustworthy right now? Named tests, hysteresis and a hold-off.

The tests (gate_tests.py, one object each, built from its registry in order) close the gate each
under its own reason bit (reasons.py):
- `turn_rate`: turning faster than `turn_rate_rad_s`; a turn also re-learns the references below
  (their levels depend on heading on a vehicle) and restarts the heading-rate history.
- `field_norm`, `dip_angle`: |B| and the inclination against references learned while the gate is
  open, each a line in temperature (gate_references.py): an uncalibrated magnetometer's
  sensitivity and hard iron move with its temperature.
- `accel_norm`: the accelerometer's norm against its value at rest: roll and pitch from gravity,
  hence the compass's tilt compensation, are wrong.
- `heading_rate_mismatch`: the compass heading moves while the gyro heading does not
  (gate_mismatch.py), with its drift-line release.
Each test fires at 1 x its threshold and releases below `hysteresis` x; the gate reopens only after
`holdoff_s` with no test firing (reported as the reason `holdoff` meanwhile). Inputs are per
observation (single compass samples, or short block means); the state machine is a loop over them,
sequential by nature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..angles import wrap_angle
from .gate_references import GateReferences
from .gate_test_base import Observation
from .gate_tests import GATE_TESTS
from .reasons import GATE_REASONS, REASON_BIT, reason_names

REASONS = GATE_REASONS
BIT = REASON_BIT


@dataclass(frozen=True)
class GateConfig:
    """Thresholds of the magnetic gate. Angles in radians."""
    reference_memory_s: float = 600.0       # memory of the references while open
    reference_relearn_s: float = 3.0        # after a turn, re-learn the reference levels this long, s
    norm_tc_prior: float = 0.005            # prior 1-sigma of the relative change per degC of |B| and of |f| at rest
    dip_tc_prior_rad: float = math.radians(0.1)  # prior 1-sigma of the dip's change per degC, rad
    field_norm_tol: float = 0.02            # relative |B| deviation that closes the gate
    dip_tol_rad: float = math.radians(1.0)  # dip deviation that closes the gate, rad
    mismatch_enabled: bool = True           # the compass-vs-gyro heading-rate test
    mismatch_rad: float = math.radians(1.0)  # compass-vs-gyro disagreement (bend of r), rad
    mismatch_window_s: float = 10.0         # window of its second difference, s
    mismatch_smooth_s: float = 1.0          # moving average of r before testing
    mismatch_sigma: float = 2.0             # allowance: mismatch_rad + k*sqrt(ARW^2 t + (drift t)^2)
    mismatch_noise_sigma: float = 4.0       # the bend threshold is at least this many sigma of the
                                            # bend's own noise (compass noise after smoothing, ARW)
    mismatch_drift_rad_s: float = math.radians(0.005)  # drift-estimate uncertainty allowed while shut (floor), rad/s
    mismatch_settle_s: float = 30.0         # r must be this long stable before reopening
    mismatch_max_s: float = 600.0           # after this, a stable compass is accepted as it is
    mismatch_line_s: float = 120.0          # r a straight line this long, drifting: accepted, s (0 = off)
    mismatch_line_rms_rad: float = math.radians(0.5)  # rms of r about that line that still counts as straight, rad
    turn_rate_enabled: bool = True          # close while turning (vehicles); off for turntables
    turn_rate_rad_s: float = math.radians(2.0)  # turning faster than this, rad/s
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


class MagneticGate:
    """Streaming compass gate; `update` takes observations in time order. `arw_rad_sqrt_s` (the
    gyro's angle random walk) and `reference_s` (the still period, when the references are first
    learned) are the estimator's values, passed once, not settings of the gate."""

    def __init__(self, config: GateConfig = GateConfig(), arw_rad_sqrt_s: float = np.radians(0.04),
                 reference_s: float = 30.0):
        cfg = self.cfg = config
        self.arw_rad_sqrt_s = float(arw_rad_sqrt_s)
        self.reference_s = float(reference_s)
        self.reference = GateReferences(cfg.reference_memory_s, cfg.norm_tc_prior, cfg.dip_tc_prior_rad)
        self.tests = [cls(self) for cls in GATE_TESTS]
        self._by_name = {test.name: test for test in self.tests}
        self._mismatch = self._by_name['heading_rate_mismatch']
        self._active = {test.name: False for test in self.tests}
        self._t_last_active = -np.inf
        self._open = True
        self._t_prev: float | None = None
        self._r_last = None                    # last unwrapped r (continuity across calls)
        self._obs = Observation()

    @property
    def n_drift_lines(self) -> int:
        """Drift lines the heading-rate test has accepted (gate_mismatch.py)."""
        return self._mismatch.n_drift_lines

    def take_drift_lines(self) -> list[tuple[float, float]]:
        """Drift lines accepted since the last call, as (t s, variance rad^2): the heading the gyro
        carried through the shut is that far off, so the heading filter must take the compass as it
        is (its innovation test would refuse it for `reject_max_s` more)."""
        lines, self._mismatch.drift_lines = self._mismatch.drift_lines, []
        return lines

    def set_config(self, config: GateConfig) -> None:
        """Change thresholds at run time: everything derived from them follows (the trailing
        windows take their new lengths; the learned references are kept)."""
        self.cfg = config
        self.reference.memory_s = config.reference_memory_s
        self.reference.norm_tc_prior = config.norm_tc_prior
        self.reference.dip_tc_prior_rad = config.dip_tc_prior_rad
        for test in self.tests:
            test.set_config(config)

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

    # -- heading history -----------------------------------------------------------------------
    def reset_mismatch(self) -> None:
        """Forget compass-vs-gyro history (after a time gap: the heading relation is unknown)."""
        self._mismatch.clear()
        self._by_name['turn_rate'].trail.q.clear()
        self._mismatch.frozen = None
        self._r_last = None

    def rebase(self, delta_rate_rad_s: float, t_ref_s: float) -> None:
        """The drift estimate changed by `delta_rate_rad_s` at `t_ref_s`: re-express the gyro
        heading history as if the new estimate had always been in force (continuous at t_ref_s).
        Otherwise the estimator's own correction bends r like interference does, and after a long
        coast the correction needed to catch up would keep the gate shut for ever."""
        d = float(delta_rate_rad_s)
        if d == 0.0 or not np.isfinite(d):
            return

        def shift(q):
            return type(q)((t, v + d * (t_ref_s - t)) for t, v in q)
        for trail in (*self._mismatch.trails(), self._by_name['turn_rate'].trail):
            trail.q = shift(trail.q)
        self._mismatch.rebased(shift)
        if self._r_last is not None and self._t_prev is not None:
            self._r_last += d * (t_ref_s - self._t_prev)

    # -- update -------------------------------------------------------------------------------
    def update(self, t, field_norm_t, dip_rad, heading_compass_rad, heading_gyro_rad,
               accel_m_s2, temperature_c=None, drift_sigma_rad_s: float = 0.0,
               compass_var_rad2=0.0) -> GateResult:
        """Observations (M,): time s, |B| T, dip rad, compass heading rad (wrapped), gyro heading
        rad (continuous, drift-compensated), the accelerometer's norm |f| m/s^2 (judged against its
        value at rest, learned with the field's references), temperature degC (optional).
        `drift_sigma_rad_s`: current 1-sigma of the drift estimate (widens the mismatch allowance
        while shut; the config's mismatch_drift_rad_s is the floor). `compass_var_rad2`: variance
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
        obs = self._obs
        obs.arw2 = self.arw_rad_sqrt_s ** 2
        obs.drift = float(max(cfg.mismatch_drift_rad_s, float(drift_sigma_rad_s)))
        obs.hyst = hyst = cfg.hysteresis
        # each test once per batch; per observation: the tests that may shut the gate, or must be
        # judged anyway, with their bits
        run = []
        for test in self.tests:
            test.begin(obs)
            enabled = test.enabled()
            if enabled or test.observe_disabled:
                run.append((test, test.name, REASON_BIT[test.name] if enabled else 0))
        lists = (t.tolist(), r.tolist(), psi_g.tolist(), np.asarray(field_norm_t, dtype=float).tolist(),
                 np.asarray(dip_rad, dtype=float).tolist(), temp.tolist(),
                 np.broadcast_to(np.asarray(accel_m_s2, dtype=float), (m,)).tolist(),
                 np.broadcast_to(np.asarray(compass_var_rad2, dtype=float), (m,)).tolist())
        act, holdoff_s, b_hold, ref = self._active, cfg.holdoff_s, REASON_BIT['holdoff'], self.reference
        is_open, reasons = [], []
        for obs.t, obs.r, obs.psi_g, obs.norm, obs.dip, obs.temp, obs.accel, obs.var in zip(*lists):
            t_now = obs.t
            obs.dt = t_now - self._t_prev if self._t_prev is not None else 0.0
            self._t_prev = t_now
            obs.was_open = self._open
            obs.turning = obs.turn_closes = False
            mask = 0
            for test, name, bit in run:
                x = test.value(obs, act[name])
                fired = x is not None and x > (hyst if act[name] else 1.0)
                if x is not None:
                    x = test.revise(fired, obs)
                    if x is not None:
                        fired = x > hyst
                test.decided(fired, obs)
                act[name] = fired
                if fired:
                    mask |= bit
            if mask:
                self._t_last_active = t_now
            elif t_now - self._t_last_active < holdoff_s:
                mask = b_hold
            now_open = mask == 0
            if self._open and not now_open:
                for test in self.tests:
                    test.on_shut(obs)
            elif now_open and not self._open:
                for test in self.tests:
                    test.on_reopen(obs)
            self._open = now_open
            ref.observe(t_now, obs.norm, obs.dip, obs.accel, obs.temp, obs.dt, now_open)
            is_open.append(now_open)
            reasons.append(mask)
        return GateResult(np.array(is_open, dtype=bool), np.array(reasons, dtype=np.int64))
