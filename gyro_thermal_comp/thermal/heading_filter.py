"""Output heading: gyro dead reckoning corrected towards the compass while the gate is open.

heading = psi_g + off, where psi_g integrates the drift-compensated heading rate and `off` is the
first state of a small Kalman filter fed with compass-minus-gyro measurements z = psi_c - psi_g, so
the output is as smooth as the gyro and the compass only removes slow error. States (rad, 1):
  off        random walk: gyro angle random walk N^2 per s, plus, while coasting, the growth of
             (drift sigma x coasting time)^2;
  k          gyro scale-factor error (optional): the gyro reports (1 + k) times the true turn, so
             off moves by -k x (gyro heading change); a car that always turns left would otherwise
             gain k x 360 deg per lap. Observable once the compass deviation map is known;
  d_cn, d_sn compass deviation harmonics n = 1..`harmonics`:
             delta(psi) = sum_n d_cn (cos n psi - cos n psi0) + d_sn (sin n psi - sin n psi0),
             so z = off + delta(psi) + noise.
  beta       (with `norm_tie`) the horizontal field strength's relative offset from the first sample's.
The deviation is anchored to zero at the start heading psi0 (the start heading is defined by the
compass there, as the scoring does). Hard iron gives n = 1, soft iron n = 2 (a constant tilt error
looks like n = 1 too); with the deviation in the state a turn does not drag the heading towards
the deviated compass, and once the headings have been visited the map is known. A static unit has
h = 0 and this is a one-state filter.

The horizontal field strength ties the deviation down before the headings repeat (`norm_tie`): the
iron that turns the measured field also stretches it, with the same coefficients, so |B_h| measures
beta and the deviation harmonics (field_strength_tie.py), with its own innovation test.

Where the deviation is evaluated matters: at psi_g + off, the gyro noise that `off` models also
moves the evaluation point; at the same block's compass heading, the compass noise in z does. Either
way a deviation slope of -1 or +1 would "explain" that noise and the coefficients run away. The
previous block's compass heading shares no noise with the current measurement (and holds no gyro
error at all), so that is where h is evaluated.

A compass measurement whose innovation exceeds `reject_sigma` standard deviations is refused, unless
the compass has kept disagreeing long and steadily enough that the filter must be what is wrong
(compass_refusal.py). Each turn (compass heading change of `min_turn_rad`) adds
(scale_factor_sigma x turn)^2 to the offset variance first, for what the scale-factor state does not
capture.

Corrections reach the output through a slew limit, so the output never jumps when the gate reopens
after a long outage (except after a time gap, where a jump is honest): the rate is `max_slew_rad_s`,
or the remaining correction / `settle_s` if that is faster, so a large correction the filter has
become sure of (a vehicle closing its first lap makes the scale factor and the deviation map
observable at once) is in within a few `settle_s`, not held back for tens of seconds. The variance
returned is the output's: the offset variance plus the square of the correction still to come.
The slew limit starts `align_s` after the first compass sample: before that the output follows the
filter, which averages the compass down from one sample's noise (0.28 deg for the simulated unit)
at 1/sqrt(n); slewed, the output kept most of the first sample's error for seconds. Nothing
downstream has a heading to protect yet.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..angles import wrap_angle
from .compass_refusal import CompassRefusals
from .field_strength_tie import FieldStrengthTie


@dataclass(frozen=True)
class HeadingFilterConfig:
    harmonics: int = 2                                # compass deviation harmonics (0 = none)
    deviation_sigma_rad: float = math.radians(10.0)   # prior 1-sigma per deviation coefficient
    deviation_q_rad2_s: float = math.radians(0.01) ** 2  # slow change of the deviation
    scale_factor_state: bool = True                   # learn the gyro scale-factor error
    scale_factor_prior: float = 0.01                  # its prior 1-sigma (calibrated sensitivity)
    scale_factor_sigma: float = 0.003                 # extra heading variance per rad turned
    min_turn_rad: float = math.radians(10.0)          # heading change that counts as a turn
    max_slew_rad_s: float = math.radians(0.5)         # output correction rate limit (0 = none)
    settle_s: float = 2.0                             # or correction left / settle_s if faster, s (0 = slew only)
    align_s: float = 5.0                              # start-up: no slew this long after the first compass sample, s
    norm_tie: bool = True                             # the horizontal field strength measures the deviation too
    norm_offset_sigma: float = 0.2                    # prior 1-sigma of beta, that strength's relative offset
    norm_offset_q_s: float = 5e-6                     # its random walk (levelling on the move, gain, local field), 1/s
    reject_sigma: float = 5.0                         # compass innovation test (0 = off)
    reject_max_s: float = 120.0                       # disagreeing this long and steadily:
    reject_steady_rad: float = math.radians(1.0)      # ... accept and re-converge


def heading_variance_growth(arw_rad_sqrt_s: float, drift_sigma_rad_s: float, tau_s, dt_s):
    """Growth of the heading variance, rad^2, over dt_s (s) after tau_s (s) without a compass
    correction: the angle random walk, plus the drift uncertainty integrated over the whole coast
    (an error in D_hat grows the heading error linearly in time; docs/design.md eq. 13)."""
    return arw_rad_sqrt_s ** 2 * dt_s + drift_sigma_rad_s ** 2 * ((tau_s + dt_s) ** 2 - tau_s ** 2)


class HeadingFilter:
    """Kalman filter on the gyro-heading offset (+ scale factor, + compass deviation harmonics).
    `arw_rad_sqrt_s`: the gyro's angle random walk, the sensor's value (not a tuning)."""

    def __init__(self, config: HeadingFilterConfig = HeadingFilterConfig(), arw_rad_sqrt_s: float = math.radians(0.04)):
        self.cfg = config
        self.arw_rad_sqrt_s = float(arw_rad_sqrt_s)
        self.i_k = 1 if config.scale_factor_state else None   # index of the scale-factor state
        self.i_d = 1 + int(config.scale_factor_state)          # first deviation coefficient
        self.n = self.i_d + 2 * int(config.harmonics)
        self.i_b = None                                         # index of beta (norm_tie)
        if config.norm_tie and config.harmonics > 0:
            self.i_b, self.n = self.n, self.n + 1
        self._q_rw = self._random_walk_q()
        self._tie = None if self.i_b is None else FieldStrengthTie(self.n, self.i_b, self.i_d, config.harmonics)
        self.x = np.zeros(self.n)
        self.P = np.zeros((self.n, self.n))
        self.initialized = False
        self.t_aligned = math.inf    # the slew limit applies from this time on, s
        self.psi0 = 0.0
        self.out_off = 0.0           # slew-limited offset actually applied to the output
        self.tau_coast = 0.0         # s since the last compass correction
        self.t = None                # time the filter is propagated to
        self._psi_g_last = None      # gyro heading when the scale-factor state was last applied
        self._psi_turn_ref = 0.0     # compass heading at the last counted turn
        self._psi_prev = 0.0         # compass heading of the previous block (deviation terms)
        self._refusals = CompassRefusals(config.reject_max_s, config.reject_steady_rad)
        self.carried: dict | None = None   # the map of an earlier run (`carry_over`)

    def learned(self) -> dict | None:
        """What the filter learned of the vehicle rather than of this run: the gyro scale factor
        and the compass deviation map with the heading it is anchored at, and their covariance
        (plain data); None before the first compass sample or without such states."""
        m = slice(1, self.i_d + 2 * self.cfg.harmonics)
        if not self.initialized or m.stop <= 1:
            return None
        return {'psi0_rad': float(self.psi0), 'x': self.x[m].tolist(), 'P': self.P[m, m].tolist()}

    def carry_over(self, learned: dict) -> None:
        """Start from the map of an earlier run (`learned()`), before the first compass sample.
        ValueError if it does not fit this filter."""
        k = self.i_d + 2 * self.cfg.harmonics - 1
        x = np.asarray(learned['x'], dtype=float).reshape(-1)
        P = np.asarray(learned['P'], dtype=float)
        psi0 = float(learned['psi0_rad'])
        if x.size != k or P.shape != (k, k) or not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))
                                                       and math.isfinite(psi0)):
            raise ValueError(f'heading map must hold {k} finite states with their covariance')
        if np.any(np.diag(P) < 0):
            raise ValueError('heading map covariance has a negative variance')
        self.carried = {'psi0_rad': psi0, 'x': x.tolist(), 'P': (0.5 * (P + P.T)).tolist()}

    def initialize(self, t_s: float, off_rad: float, psi0_rad: float, off_var: float,
                   psi_g_rad: float = 0.0, b_h_t: float = math.nan) -> None:
        """Start at time t_s from one compass reading: psi0 = psi_g + off (rad); b_h_t: its
        horizontal field strength, T (NaN: no field-strength tie). With a map of an earlier run
        (`carry_over`) the deviation stays anchored where that run began: the offset is the
        reading less the deviation the map predicts here, with the map's uncertainty."""
        cfg = self.cfg
        self.x[:] = 0.0
        self.x[0] = off_rad
        var = [off_var] + ([cfg.scale_factor_prior ** 2] if self.i_k else []) + \
            [cfg.deviation_sigma_rad ** 2] * (2 * cfg.harmonics) + \
            ([cfg.norm_offset_sigma ** 2] if self.i_b is not None else [])
        if self._tie is not None:
            self._tie.start(b_h_t)
        self.P = np.diag(var)
        self.psi0 = self._psi_turn_ref = self._psi_prev = float(psi0_rad)
        if self.carried is not None:
            m = slice(1, self.i_d + 2 * cfg.harmonics)        # scale factor and deviation map
            self.psi0 = self.carried['psi0_rad']
            self.x[m] = np.asarray(self.carried['x'])
            self.P[m, m] = np.asarray(self.carried['P'])
            h = self._measurement_rows(np.array([float(psi0_rad)]))[0]
            self.x[0] = off_rad - float(h[m] @ self.x[m])
            ph = self.P[m, m] @ h[m]
            self.P[0, 0] = off_var + float(h[m] @ ph)
            self.P[0, m] = self.P[m, 0] = -ph
        self._psi_g_last = float(psi_g_rad)
        self.out_off = float(self.x[0])
        self.t = float(t_s)
        self.t_aligned = float(t_s) + cfg.align_s
        self.tau_coast = 0.0
        self.initialized = True

    def state(self) -> tuple:
        """What the filter has learned and where it is (not the output's slew position), to restore."""
        return (self.x.copy(), self.P.copy(), self.t, self.tau_coast, self._psi_g_last, self._psi_turn_ref,
                self._psi_prev, self._refusals.t_start, self._refusals.sums.copy())

    def restore(self, state: tuple) -> None:
        """Back to a `state()`: the output offset stays where it is and slews to the restored one."""
        x, P, self.t, self.tau_coast, self._psi_g_last, self._psi_turn_ref, self._psi_prev, t_reject, rej = state
        self.x, self.P = x.copy(), P.copy()
        self._refusals.t_start, self._refusals.sums = t_reject, rej.copy()

    def inflate(self, var_rad2: float) -> None:
        """Add variance to the offset (e.g. after a time gap)."""
        self.P[0, 0] += var_rad2

    @property
    def sigma_rad(self) -> float:
        return math.sqrt(max(self.P[0, 0], 0.0))

    @property
    def scale_factor(self) -> float:
        return float(self.x[self.i_k]) if self.i_k else 0.0

    @property
    def n_rejected(self) -> int:
        """Compass measurements refused so far."""
        return self._refusals.n_rejected

    def run(self, t, z, z_var, psi_g, use, sigma_d_rad_s: float, jump: bool = False, b_h_t=None) -> np.ndarray:
        """Propagate to each block time t[b] (s) and, where use[b], correct with the compass
        measurement z[b] = psi_compass - psi_g (rad, any branch) of variance z_var[b] (rad^2).
        psi_g[b] (rad, continuous) + z[b] is the compass heading, at which the deviation terms are
        evaluated and turns are counted. `sigma_d_rad_s` (1-sigma of the drift estimate) makes the
        variance grow as (sigma_d x coasting time)^2. `jump`: the first step moves the output at
        once. b_h_t[b]: the block's horizontal field strength, T (None: no field-strength update).
        Returns (m, 4): slew-limited output offset, its variance, coasting time, and
        1.0 where a measurement was used (0.0 where none was offered or it was refused)."""
        cfg = self.cfg
        m = len(t)
        outs = np.empty((m, 4))
        if m == 0:
            return outs
        # one branch for the whole batch: z continuous around the offset at the start
        z = np.atleast_1d(self.x[0] + wrap_angle(np.asarray(z, dtype=float) - self.x[0]))
        psi_g = np.asarray(psi_g, dtype=float)
        psi_c = psi_g + z
        t = np.asarray(t, dtype=float)
        i_k, n = self.i_k, self.n
        # what the state does not change, for the whole batch at once: the steps and the measurement
        # rows (the deviation at the previous block's compass heading); the loop does only the filter
        dt_l = np.maximum(np.diff(t, prepend=self.t), 0.0).tolist()
        h_rows = self._measurement_rows(np.concatenate(([self._psi_prev], psi_c[:-1])))
        self._psi_prev = float(psi_c[-1])
        tie = self._tie
        norm_rows = None if tie is None else tie.rows(psi_c, b_h_t)
        # per-block scalars as Python floats: numpy scalar arithmetic costs ~10x more
        t_l, z_l, psi_g_l, psi_c_l = t.tolist(), z.tolist(), psi_g.tolist(), psi_c.tolist()
        z_var_l = np.broadcast_to(np.asarray(z_var, dtype=float), (m,)).tolist()
        use_l = np.broadcast_to(np.asarray(use, dtype=bool), (m,)).tolist()
        min_turn, sf_sigma, slew = cfg.min_turn_rad, cfg.scale_factor_sigma, cfg.max_slew_rad_s
        settle_rate = 1.0 / cfg.settle_s if cfg.settle_s > 0 else 0.0
        # the innovation test inline; a failed one goes to the run of refusals
        refusals = self._refusals
        test_off, reject2 = cfg.reject_sigma <= 0, cfg.reject_sigma * cfg.reject_sigma
        # heading_variance_growth, inlined below with its factors once
        arw2, sd2 = self.arw_rad_sqrt_s ** 2, sigma_d_rad_s ** 2
        self.P = P = np.ascontiguousarray(self.P)
        x = self.x
        # the random walks of the deviation coefficients and beta: one vector on P's diagonal view
        # (the offset's growth is computed below, the scale factor is a constant)
        diag = P.reshape(-1)[::n + 1]
        q_rw = self._q_rw
        tau, out_off, t_aligned = self.tau_coast, self.out_off, self.t_aligned
        psi_g_last, psi_turn_ref = self._psi_g_last, self._psi_turn_ref
        rows = []
        for b in range(m):
            tb = t_l[b]
            dt = dt_l[b]
            # -- time update
            psi_g_b = psi_g_l[b]
            turn_g = psi_g_b - psi_g_last
            if i_k is not None and abs(turn_g) > min_turn:
                # only whole turns: applied to every small step, k would multiply the gyro noise
                # that `off` already models and could "explain" it
                x[0] -= x[i_k] * turn_g                    # F = I - turn_g e0 e_k^T
                col = P[:, i_k].copy()
                P[0, :] -= turn_g * P[i_k, :]
                P[:, 0] -= turn_g * col
                P[0, 0] += turn_g * turn_g * P[i_k, i_k]
                psi_g_last = psi_g_b
            elif i_k is None:
                psi_g_last = psi_g_b
            p00 = float(P[0, 0]) + (arw2 * dt + sd2 * ((tau + dt) ** 2 - tau ** 2))   # heading_variance_growth
            if q_rw is not None:
                diag += q_rw * dt
            psi = psi_c_l[b]
            turned = psi - psi_turn_ref
            if abs(turned) > min_turn:
                p00 += (sf_sigma * turned) ** 2
                psi_turn_ref = psi
            P[0, 0] = p00
            # -- measurement update
            used = 0.0
            if use_l[b]:
                h = h_rows[b]
                # ndarray.dot: the same BLAS call as @, a third of its overhead on these sizes
                nu = z_l[b] - float(h.dot(x))
                if abs(nu) > math.pi:  # only after a large jump inside the batch
                    nu = wrap_angle(nu)
                ph = P.dot(h)
                s = float(h.dot(ph)) + z_var_l[b]
                if test_off or nu * nu <= reject2 * s:
                    refusals.t_start = None
                    refused = False
                else:
                    refused = refusals.refuse(tb, nu)
                    if not refused:
                        P[0, 0] += nu * nu  # a long, steady disagreement: re-converge on the compass
                if not refused:
                    x += ph * (nu / s)
                    # np.outer(ph, ph / s) as a rank-1 product: each entry the one rounded product
                    P -= ph.reshape(n, 1).dot((ph / s).reshape(1, n))
                    used = 1.0
                    if norm_rows is not None and norm_rows[1][b]:
                        tie.update(x, P, norm_rows[2][b], norm_rows[0][b], z_var_l[b], reject2)
            tau = 0.0 if used else tau + dt
            x0 = float(x[0])
            if (jump and b == 0) or slew <= 0 or tb < t_aligned:
                out_off = x0
            else:
                lag = x0 - out_off
                lim = max(slew, abs(lag) * settle_rate) * dt
                out_off += min(max(lag, -lim), lim)
            lag = x0 - out_off
            rows.append((out_off, float(P[0, 0]) + lag * lag, tau, used))
        self.t, self.tau_coast, self.out_off = t_l[-1], tau, out_off
        self._psi_g_last, self._psi_turn_ref = psi_g_last, psi_turn_ref
        self.P = 0.5 * (P + P.T)
        outs[:] = rows
        return outs

    def _random_walk_q(self):
        """Per-state random-walk densities (n,), 1/s in the states' units squared, or None if none."""
        cfg = self.cfg
        q = np.zeros(self.n)
        q[self.i_d:self.i_d + 2 * cfg.harmonics] = cfg.deviation_q_rad2_s
        if self.i_b is not None:
            q[self.i_b] = cfg.norm_offset_q_s
        return q if q.any() else None

    def _measurement_rows(self, psi_h: np.ndarray) -> np.ndarray:
        """Rows h (m, n) of z = h . x at the compass headings psi_h (rad): 1 for the offset, 0 for the
        scale factor, the deviation harmonics' change from the start heading psi0."""
        h = np.zeros((psi_h.size, self.n))
        h[:, 0] = 1.0
        for k in range(1, self.cfg.harmonics + 1):
            j = self.i_d + 2 * k - 2
            h[:, j] = np.cos(k * psi_h) - math.cos(k * self.psi0)
            h[:, j + 1] = np.sin(k * psi_h) - math.sin(k * self.psi0)
        return h
