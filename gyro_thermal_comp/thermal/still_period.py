"""`StillPeriod`: the unit is assumed motionless for its first seconds (docs/design.md eq. 11).

Its mean rates give the initial biases (c0 = mean(w) - a0 (T0 - t_ref)), its temperature T0, its
compass scatter the compass noise, and the z gyro's successive differences its angle random walk as
the stream carries it: N^2 = var(w) x dt for samples of white noise var(w) every dt (a logger that
keeps 1 Hz point samples of a 20 Hz sensor carries its noise unfiltered: 0.12 deg/sqrt(s) where the
sensor's own density is far less). It ends early if the gyro heading moves by `motion_limit_rad`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .drift_model import DriftModel


@dataclass(frozen=True)
class StillResult:
    mean_rates_rad_s: np.ndarray       # (3,) mean gyro over the still period
    temperature_c: float | None        # mean temperature, None if none was read
    compass_var_rad2: float | None     # compass noise (scatter about a line), None if too few samples
    arw2_rad2_s: float | None          # z gyro angle random walk^2, rad^2/s, None if too few samples
    arw_samples: int                   # successive differences behind it


class StillPeriod:
    def __init__(self, duration_s: float, motion_limit_rad: float, compass_var_floor_rad2: float):
        self.duration_s = duration_s
        self.motion_limit_rad = motion_limit_rad
        self.compass_var_floor_rad2 = compass_var_floor_rad2
        self.end_s: float | None = None   # set by `begin`; moved earlier if the unit moves
        self._n = 0
        self._gyro_sum = np.zeros(3)
        self._temp_sum = 0.0
        self._temp_n = 0
        self._psi0: float | None = None   # gyro heading at its first sample, rad
        self._offsets: list[np.ndarray] = []   # (t, compass - gyro heading, unwrapped) blocks
        self._last: tuple[float, float] | None = None   # the latest (t, z rate)
        self._diff2 = 0.0                 # sum of squared successive z-rate differences, (rad/s)^2
        self._span = 0.0                  # sum of the intervals between them, s
        self._n_diff = 0

    def begin(self, t_origin_s: float) -> None:
        self.end_s = t_origin_s + self.duration_s

    def running_mean(self, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The drift estimate during the still period: the running mean of the gyro so far
        (z as D_hat (N,), x/y as biases (N, 2)), rad/s."""
        run = (np.cumsum(gyro, axis=0) + self._gyro_sum) / (self._n + np.arange(1, gyro.shape[0] + 1))[:, None]
        return run[:, 2], run[:, :2]

    def first_motion(self, t: np.ndarray, psi_g: np.ndarray) -> int | None:
        """Index of the first sample whose gyro heading (rad) left the start by the motion limit
        before the end; None if none, or if it is the stretch's last sample (nothing to cut)."""
        psi0 = self._psi0 if self._psi0 is not None else psi_g[0]
        moved = (np.abs(psi_g - psi0) > self.motion_limit_rad) & (t < self.end_s)
        if not np.any(moved):
            return None
        k = int(np.argmax(moved))
        return k if k + 1 < t.size else None

    def add_imu(self, t: np.ndarray, gyro: np.ndarray, temp_c: np.ndarray, temp_known: np.ndarray,
                psi_g: np.ndarray) -> None:
        if t.size:
            tt, wz = t, gyro[:, 2]
            if self._last is not None:
                tt, wz = np.concatenate(([self._last[0]], t)), np.concatenate(([self._last[1]], wz))
            self._diff2 += float(np.sum(np.diff(wz) ** 2))
            self._span += float(tt[-1] - tt[0])
            self._n_diff += tt.size - 1
            self._last = (float(t[-1]), float(gyro[-1, 2]))
        self._n += gyro.shape[0]
        self._gyro_sum = self._gyro_sum + gyro.sum(axis=0)
        self._temp_sum += float(temp_c[temp_known].sum())
        self._temp_n += int(np.count_nonzero(temp_known))
        if self._psi0 is None:
            self._psi0 = float(psi_g[0])

    def add_compass(self, t: np.ndarray, offset_rad: np.ndarray) -> None:
        """Compass-minus-gyro headings (rad, wrapped) at compass stamps t (s)."""
        self._offsets.append(np.column_stack((t, offset_rad[0] + np.unwrap(offset_rad - offset_rad[0]))))

    def finish(self) -> StillResult:
        mean = self._gyro_sum / self._n if self._n else np.zeros(3)
        temp = self._temp_sum / self._temp_n if self._temp_n else None
        var = None
        if self._offsets:
            tz = np.concatenate(self._offsets, axis=0)
            if tz.shape[0] >= 10:
                tt = tz[:, 0] - tz[0, 0]
                resid = tz[:, 1] - np.polyval(np.polyfit(tt, tz[:, 1], 1), tt)
                var = max(float(np.var(resid)), self.compass_var_floor_rad2)
        self._offsets = []
        arw2 = None
        if self._n_diff >= 10 and self._span > 0:
            arw2 = 0.5 * self._diff2 / self._n_diff * (self._span / self._n_diff)
        return StillResult(mean, temp, var, arw2, self._n_diff)


def still_covariance(P_prior: np.ndarray, i_c: int, h0: np.ndarray, var_still: float) -> np.ndarray:
    """Covariance after the still period measured the drift D0 = h0 . x at its temperature.

    The other parameters keep their prior P_oo; `constant` is c = D0 - sum_{j != c} h0_j x_j, so
    Var(c) = var_still + h0_o P_oo h0_o and Cov(x_o, c) = -P_oo h0_o (docs/design.md eq. 12).
    Measuring D0 at T0 != t_ref does not pin c itself, and a later innovation at T0 must not be
    pushed into `a`."""
    n = P_prior.shape[0]
    o = np.array([j for j in range(n) if j != i_c], dtype=int)
    P = np.zeros((n, n))
    P_oo = P_prior[np.ix_(o, o)]
    ph = P_oo @ h0[o]
    P[np.ix_(o, o)] = P_oo
    P[o, i_c] = P[i_c, o] = -ph
    P[i_c, i_c] = var_still + h0[o] @ ph
    return P



def initial_state(model: DriftModel, bias_rad_s: float, temperature_c: float, prior_sigmas: np.ndarray,
                  warm: dict | None, var_still: float) -> tuple[np.ndarray, np.ndarray]:
    """Initial parameters and covariance at the end of the still period, which measured the drift
    `bias_rad_s` (variance `var_still`, (rad/s)^2) at `temperature_c`. A warm start (`warm`: x, P
    of an earlier run) keeps every parameter but `constant`, which is re-measured."""
    P0 = np.diag(prior_sigmas ** 2)
    known = {}
    if warm is not None:
        known = {name: float(v) for name, v in zip(model.names, warm['x']) if name != 'constant'}
        if warm.get('P') is not None:
            P0 = np.asarray(warm['P'], dtype=float).copy()
    x0 = model.initial_state(float(bias_rad_s), temperature_c, known)
    i_c = model.index('constant')
    if i_c is not None:
        h0 = model.rows(model.neutral_inputs(temperature_c))[0]
        P0 = still_covariance(P0, i_c, h0, var_still)
    return x0, P0
