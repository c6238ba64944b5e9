"""Strong-tracking (fading-memory) Kalman filter over the drift-model parameters (docs/design.md eq. 3-10).

State x = drift-model parameters (size set by the model), Phi = I. The fading factor s >= 1
discounts old windows: P_{k+1|k} = s * P_k + Q, which is `filterpy.kalman.KalmanFilter` with
`alpha = sqrt(s)` (docs/design.md eq. 10). Optionally the factor is multiplied each step by Zhou's strong
tracking factor lambda_k >= 1 computed from the innovation sequence, so the memory shortens only
when the innovations say the model is no longer right.

Protections (the learned parameters are the product; never lose them):
- measurements or states that are not finite are refused and the previous state kept;
- an innovation beyond `reject_sigma` standard deviations is refused (an undetected magnetic
  disturbance looks like this) unless `max_rejections` in a row were refused, which means the
  drift really moved: then P is widened along the measurement by the disagreement and it is taken;
- while nothing is measured, P keeps fading but each variance is capped at `p_max` (the prior), so
  the first window after a long outage or a long constant-temperature hold cannot swing the
  parameters further than the prior allows;
- an update that would leave P not symmetric positive definite is refused;
- divergence (`FilterHealth`: innovations persistently far beyond their predicted spread) puts the
  state back to the last good parameters with P widened to the prior, and is counted (`n_resets`).
  Only a good state judged on at least half a health window of innovations and at most two health
  windows old is gone back to: an older one describes another temperature and another drift, and
  a filter never consistent since its start would return to its first guess. Without one, the
  current state is kept and only P widened.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from ..angles import wrap_angle


@dataclass(frozen=True)
class StepResult:
    innovation: float       # y - H x_pred, rad/s (NaN if no measurement)
    innovation_var: float   # H P_pred H^T + R, (rad/s)^2
    fading: float           # total factor applied to P this step (s * lambda)
    accepted: bool


class StrongTrackingKF:
    """Fading-memory KF with scalar measurements y = h . x + v."""

    def __init__(self, x0, P0, Q, fading_s: float = 1.0, adaptive: bool = False,
                 zhou_rho: float = 0.95, zhou_beta: float = 1.0, zhou_max: float = 20.0,
                 reject_sigma: float = 5.0, max_rejections: int = 3, p_max=None, health_windows: int = 30,
                 diverged_nis: float = 9.0):
        x0 = np.asarray(x0, dtype=float).reshape(-1)
        n = x0.size
        if fading_s < 1.0:
            raise ValueError('fading factor s must be >= 1')
        self.kf = KalmanFilter(dim_x=n, dim_z=1)
        self.kf.F = np.eye(n)
        self.kf.x = x0.reshape(n, 1).copy()
        self.kf.P = np.array(P0, dtype=float).reshape(n, n).copy()
        self.kf.Q = np.array(Q, dtype=float).reshape(n, n).copy()
        self.fading_s = float(fading_s)
        self.kf.alpha = np.sqrt(self.fading_s)
        self.adaptive = bool(adaptive)
        self.zhou_rho, self.zhou_beta, self.zhou_max = float(zhou_rho), float(zhou_beta), float(zhou_max)
        self.reject_sigma = float(reject_sigma)
        self.max_rejections = int(max_rejections)
        self.p_max = np.diag(self.kf.P).copy() if p_max is None else np.asarray(p_max, dtype=float)
        self._v_innov = None  # Zhou's running innovation variance V_k
        self.rejections_in_row = 0
        self.health = FilterHealth(health_windows, diverged_nis, self.kf.x[:, 0])
        self.n_resets = 0
        self.n_updates = 0
        self.n_rejected = 0

    @property
    def x(self) -> np.ndarray:
        return self.kf.x[:, 0].copy()

    @property
    def P(self) -> np.ndarray:
        return self.kf.P.copy()

    def set_state(self, x, P=None) -> None:
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.size != self.kf.dim_x or not np.all(np.isfinite(x)):
            raise ValueError(f'state must be {self.kf.dim_x} finite values')
        self.kf.x = x.reshape(-1, 1).copy()
        if P is not None:
            P = np.asarray(P, dtype=float).reshape(self.kf.dim_x, self.kf.dim_x)
            if not np.all(np.isfinite(P)):
                raise ValueError('covariance must be finite')
            self.kf.P = 0.5 * (P + P.T)

    def _zhou_lambda(self, gamma: float, h: np.ndarray, R: float) -> float:
        """Zhou's suboptimal fading factor from the innovation variance (scalar measurement)."""
        g2 = gamma * gamma
        rho = self.zhou_rho
        self._v_innov = g2 if self._v_innov is None else (rho * self._v_innov + g2) / (1 + rho)
        m = float(h @ self.kf.P @ h) * self.fading_s
        nmat = self._v_innov - float(h @ self.kf.Q @ h) - self.zhou_beta * R
        if m <= 0:
            return 1.0
        return float(np.clip(nmat / m, 1.0, self.zhou_max))

    def _cap(self) -> None:
        d = np.diag(self.kf.P)
        scale = np.sqrt(np.minimum(1.0, self.p_max / np.maximum(d, 1e-300)))
        if np.any(scale < 1.0):  # congruence with a diagonal: stays symmetric positive definite
            self.kf.P = self.kf.P * scale[:, None] * scale[None, :]

    def step(self, y: float | None = None, h=None, R: float | None = None) -> StepResult:
        """One filter step (one update window): fade/predict, then update if `y` is given."""
        have = y is not None and h is not None and R is not None
        if have:
            h = np.asarray(h, dtype=float).reshape(-1)
            have = bool(np.isfinite(y) and np.all(np.isfinite(h)) and np.isfinite(R) and R > 0)
        x_prev, p_prev = self.kf.x.copy(), self.kf.P.copy()
        lam = 1.0
        gamma = float(y - h @ self.kf.x[:, 0]) if have else np.nan
        if have and self.adaptive:
            lam = self._zhou_lambda(gamma, h, R)
        self.kf.alpha = np.sqrt(self.fading_s * lam)
        self.kf.predict()   # P = alpha^2 P + Q with alpha^2 = s lambda (docs/design.md eq. 10)
        self._cap()
        if not have:
            return StepResult(np.nan, np.nan, self.fading_s * lam, False)
        s_var = float(h @ self.kf.P @ h) + R
        if abs(gamma) > self.reject_sigma * np.sqrt(s_var):
            if self.rejections_in_row < self.max_rejections:
                self.rejections_in_row += 1
                self.n_rejected += 1
                return StepResult(gamma, s_var, self.fading_s * lam, False)
            # refused max_rejections times in a row: the drift really moved. Widen P along h by
            # the disagreement so this and the next windows can move the state.
            hh = float(h @ h)
            self.kf.P = self.kf.P + np.outer(h, h) * (gamma * gamma / (hh * hh))
            s_var = float(h @ self.kf.P @ h) + R
        self.kf.update(np.array([[y]]), R=np.array([[R]]), H=h.reshape(1, -1))
        self.kf.P = 0.5 * (self.kf.P + self.kf.P.T)
        if not (np.all(np.isfinite(self.kf.x)) and _positive_definite(self.kf.P)):
            self.kf.x, self.kf.P = x_prev, p_prev  # never lose the learned parameters
            self.n_rejected += 1
            return StepResult(gamma, s_var, self.fading_s * lam, False)
        self.rejections_in_row = 0
        self.n_updates += 1
        if self.health.diverged(gamma * gamma / s_var, self.kf.x[:, 0]):
            # innovations persistently far beyond their predicted spread: the filter is overconfident
            # in a wrong state. Go back to the last good parameters, uncertain enough to re-learn.
            if self.health.good_is_recent():
                self.kf.x = self.health.good_x.reshape(-1, 1).copy()
            self.kf.P = np.diag(np.maximum(np.diag(self.kf.P), self.p_max))
            self.n_resets += 1
        return StepResult(gamma, s_var, self.fading_s * lam, True)


def _positive_definite(P: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(P)
        return True
    except np.linalg.LinAlgError:
        return False


class FilterHealth:
    """Normalised innovation squared (NIS = innovation^2 / its predicted variance, mean 1 for a
    consistent filter) over the last `windows` accepted updates. `good_x` is the newest state at
    which the mean was unremarkable (<= 2); a full history averaging over `diverged_nis` is a
    divergence (then the history restarts)."""

    def __init__(self, windows: int, diverged_nis: float, x0: np.ndarray):
        self.windows, self.diverged_nis = int(windows), float(diverged_nis)
        self._nis: deque = deque(maxlen=self.windows)
        self.good_x = np.array(x0, dtype=float)
        self.good_age = None    # updates since good_x was recorded (None: never)

    def diverged(self, nis: float, x: np.ndarray) -> bool:
        self._nis.append(float(nis))
        if self.good_age is not None:
            self.good_age += 1
        mean = sum(self._nis) / len(self._nis)
        if len(self._nis) == self.windows and mean > self.diverged_nis:
            self._nis.clear()
            return True
        if mean <= 2.0 and 2 * len(self._nis) >= self.windows:
            self.good_x = np.array(x, dtype=float)
            self.good_age = 0
        return False

    def good_is_recent(self) -> bool:
        return self.good_age is not None and self.good_age <= 2 * self.windows


class DriftWindow:
    """Accumulates one update window and forms the drift measurement (docs/design.md eq. 4-6, exact form).

    q(t) = psi_g(t) + I_D(t) - psi_c(t), where psi_g integrates the compensated heading rate and
    I_D(t) = int_{t0}^{t} g D_hat dt is what was taken out of it (g = cos(roll)/cos(pitch) maps the
    z gyro into heading rate), so q is the raw gyro heading minus the compass heading. Averaging q
    over the compass samples of a start edge and of an end edge (length `edge_s`; 0 = the paper's
    single samples) gives

        q1 - q0 = int w(t) g (D - D_hat) dt + int w g D_hat dt + noise,  L = mean(tau1) - mean(tau0)
        y = (q1 - q0) / L  and  h = (I_H(tau1) - I_H(tau0)) / L  (same weights w on [T, Tdot, 1]),

    i.e. y = D_hat_mean + dpsi / dt with D_hat and H both the w-weighted window means of what was
    applied; a positive true drift gives a positive y. Averaging each edge over n compass samples
    divides the compass part of the noise by sqrt(n) at the cost of a window shorter by one edge.
    """

    def __init__(self, t0: float, t1: float, edge_s: float, n_params: int):
        self.t0, self.t1 = float(t0), float(t1)
        self.edge_s = min(float(edge_s), 0.5 * (self.t1 - self.t0))
        self.q_ref = None
        self._start, self._end = _EdgeSums(np.zeros(n_params)), _EdgeSums(np.zeros(n_params))

    def add(self, tau: np.ndarray, q: np.ndarray, i_h: np.ndarray) -> None:
        """Compass samples inside the window: times (M,), q (M,) rad, I_H (M, n) rad*regressor."""
        if tau.size == 0:
            return
        if self.q_ref is None:
            self.q_ref = float(q[0])
        q = self.q_ref + wrap_angle(q - self.q_ref)
        if self.edge_s > 0:
            for edge, mask in ((self._start, tau <= self.t0 + self.edge_s), (self._end, tau >= self.t1 - self.edge_s)):
                if np.any(mask):
                    edge.add(tau[mask], q[mask], i_h[mask])
        else:  # the paper's points: the first and the last sample
            if self._start.n == 0:
                self._start.add(tau[:1], q[:1], i_h[:1])
            self._end = _EdgeSums(np.zeros_like(self._end.i_h)).add(tau[-1:], q[-1:], i_h[-1:])

    def measurement(self, arw_rad_sqrt_s: float, compass_var_rad2: float, r_floor: float):
        """(y rad/s, h (n,), R (rad/s)^2, L s) or None if the window cannot be used."""
        n0, n1 = self._start.n, self._end.n
        if n0 == 0 or n1 == 0:
            return None
        start, end = self._start.means(), self._end.means()
        length = end.tau - start.tau
        if length <= 0.25 * (self.t1 - self.t0):
            return None
        y = (end.q - start.q) / length
        h = (end.i_h - start.i_h) / length
        r = arw_rad_sqrt_s ** 2 / length + compass_var_rad2 * (1.0 / n0 + 1.0 / n1) / length ** 2 + r_floor
        return y, h, r, length


@dataclass
class _EdgeSums:
    """Sums over the compass samples of one window edge: tau (s), q (rad), I_H; `means()` divides."""
    i_h: np.ndarray
    n: int = 0
    tau: float = 0.0
    q: float = 0.0

    def add(self, tau: np.ndarray, q: np.ndarray, i_h: np.ndarray) -> '_EdgeSums':
        self.n += int(tau.size)
        self.tau += float(tau.sum())
        self.q += float(q.sum())
        self.i_h = self.i_h + i_h.sum(axis=0)
        return self

    def means(self) -> '_EdgeSums':
        return _EdgeSums(self.i_h / self.n, self.n, self.tau / self.n, self.q / self.n)
