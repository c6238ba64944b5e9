"""`EstimatorConfig`: every setting of the STKF heading method, with the defaults' reasons."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..input_guard import CONFIRM_SAMPLES, MAX_JUMP_S
from .drift_model import CURVATURE_TERMS, SCALE_FACTOR_TERMS, DriftModel, Term
from .heading_filter import HeadingFilterConfig
from .magnetic_gate import GateConfig
from .model_file import DriftModelFile
from .model_inputs import ModelInputs
from .sampling import EDGE_SAMPLES, SMOOTH_SAMPLES, WINDOW_SAMPLES, at_least
from .stkf import StrongTrackingKF


@dataclass(frozen=True)
class EstimatorConfig:
    """Defaults suit an ADXRS623-class gyro (0.04 deg/s/sqrt(Hz)) at 100 Hz-1 kHz with a compass."""
    name: str = 'stkf'                        # method name in reports
    # drift model
    terms: tuple[str | Term, ...] = CURVATURE_TERMS  # names or Terms; PAPER_TERMS for the paper's a, b, c exactly
    scale_factor: bool = False                # add k(T) = k1 (T - t_ref) + k0 terms (needs rotation)
    temperature_ref_c: float = 25.0           # temperature terms use T - this, degC
    # a model file (model_file.py): its terms, input settings, priors and temperature_ref_c replace
    # the above (a node loads it from its `drift_model_file` parameter: a path, not a value)
    drift_model_file: DriftModelFile | None = field(default=None, metadata={'parameter': False})
    # parameter learning (STKF)
    learn: bool = True                        # False: parameters fixed (baselines, replay of a calibration)
    window_s: float = 10.0                    # update interval and drift-measurement window
    edge_s: float = 1.0                       # compass averaging at each window end (0 = paper's points)
    confirm_s: float = 5.0                    # gate must stay open this long after a window
    fading_s: float = 1.002                   # s per window (docs/design.md eq. 10); 1 = plain KF
    adaptive_fading: bool = False             # Zhou's lambda_k >= 1 on top of s
    prior_sigmas: tuple[float, ...] | None = None  # per term, SI; None = the terms' defaults
    q_sigmas: tuple[float, ...] | None = None      # per term random walk per sqrt(s); None = defaults
    coast_backtest: bool = True               # what past predictions of that age missed beyond P weighs the coasting
                                              # change and widens its sigma (backtest.py, coasting.py)
    r_floor_rad_s: float = 2e-5               # model-error floor added to each window's noise, rad/s
    reject_sigma: float = 6.0                 # a window innovation beyond this many sigma is refused
    innovation_windows: int = 30              # windows behind the empirical drift uncertainty
    adaptive_r: bool = True                   # scale the windows' R by what their innovations show
    diverged_nis: float = 9.0                 # mean innovation^2/variance over 30 windows beyond this:
                                              # diverged, back to the last good parameters (inf: off)
    # sensors
    arw_rad_sqrt_s: float = math.radians(0.04)  # gyro angle random walk = noise density, rad/s/sqrt(Hz)
    latitude_deg: float | None = None         # subtract Earth rate if known (else it ends up in c)
    temp_window_s: float = 60.0               # local-regression window for T and dT/dt, s
    temp_stuck_s: float = 600.0               # a reading unchanged this long is flagged stuck, s
    temp_hold_max_s: float = 5.0              # extrapolate the temperature line at most this long, s
    declination_rad: float = 0.0              # magnetic declination, east positive, rad
    compass_block_s: float = 0.1              # compass samples are averaged in blocks this long, s
    reopen_probation_s: float = 60.0          # a disturbance seen again this soon after a reopen undoes the compass since it, s
                                              # (twice the gate's mismatch_settle_s: outlasts a disturbance's still spell that reopened it)
    compass_sigma_rad: float | None = None    # None: learned over the still period
    compass_sigma_floor_rad: float = math.radians(0.05)  # lower bound of the learned compass noise, rad
    compass_sigma_default_rad: float = math.radians(0.5)  # used until learned
    mag_timeout_s: float = 1.0                # no compass sample for this long: coasting, s
    tilt_window_s: float = 120.0              # accelerometer averaging for roll/pitch: long, so a
                                              # car's acceleration and braking average out (turning
                                              # samples, with centripetal force, are left out)
    # input plausibility: beyond the sensor's range a sample is a fault (dropped, counted). The
    # defaults are the widest common MEMS full scales: set your sensor's datasheet values.
    gyro_range_rad_s: float = 34.9            # |rate| limit per axis, rad/s
    accel_range_m_s2: float = 160.0           # |specific force| limit per axis, m/s^2 (16 g)
    field_range_t: float = 2e-3               # |field| limit per axis, T (20 gauss)
    field_norm_min_t: float = 5e-6            # |B| below this is no reading (Earth: 22-67 uT), T
    temperature_min_c: float = -55.0          # gyro temperature range, degC
    temperature_max_c: float = 150.0          # gyro temperature range, degC
    temperature_max_rate_c_s: float = 1.0     # readings off the last by more than this x dt + 2 degC: spikes, degC/s
    temperature_timeout_s: float = 10.0       # no reading this long: temperature unknown, no learning, s
    temperature_drift_c_s: float = 0.01       # meanwhile the held temperature's uncertainty grows so, degC/s
    max_time_jump_s: float = MAX_JUMP_S       # stamp jumps beyond this need confirming to be a new time base, s
    time_jump_confirm_samples: int = CONFIRM_SAMPLES  # samples in a row that confirm a stamp jump
    # start, gaps
    still_period_s: float = 30.0              # motionless at start for this long (initial bias), s
    still_motion_rad: float = math.radians(2.0)  # the still period ends early if the heading moves this much
    max_gap_s: float = 0.5                    # IMU stamps further apart: a time gap, s
    gap_rate_sigma_rad_s: float = 0.05        # heading sigma grows by this x the gap length, rad/s
    # output heading
    heading_correction: bool = True           # False: pure dead reckoning from the initial compass
    gate: GateConfig = field(default_factory=GateConfig)  # magnetic gate thresholds
    heading: HeadingFilterConfig = field(default_factory=HeadingFilterConfig)  # output heading filter

    def for_compass_period(self, period_s: float | None) -> 'EstimatorConfig':
        """The settings in force for a compass sampled every `period_s` (measured over the still
        period): every span that averages compass samples holds a few of them (sampling.py). A
        longer drift window fades as much per second as the nominal one (`fading_s` is per window);
        its Q is per second already. At 5 Hz and faster nothing changes."""
        window_s = at_least(self.window_s, period_s, WINDOW_SAMPLES)
        return replace(self, window_s=window_s, edge_s=at_least(self.edge_s, period_s, EDGE_SAMPLES),
                       fading_s=self.fading_s ** (window_s / self.window_s),
                       gate=gate_for_compass_period(self.gate, period_s))

    def memory_s(self) -> float:
        """How far back the learner remembers, s: the windows carrying all but e^-2 of its weight
        (a window k windows old weighs fading_s^-k; inf without fading)."""
        return 2.0 * self.window_s / math.log(self.fading_s) if self.fading_s > 1.0 else math.inf

    def prior_sigma_values(self, model: DriftModel) -> np.ndarray:
        """Prior 1-sigma per term, SI (the terms' defaults unless set)."""
        if self.prior_sigmas:
            return np.asarray(self.prior_sigmas, dtype=float)
        return self._from_file(model, 'prior_sigmas')

    def q_matrix(self, model: DriftModel) -> np.ndarray:
        """Parameter random walk per update window."""
        q = np.asarray(self.q_sigmas, dtype=float) if self.q_sigmas else self._from_file(model, 'q_sigmas')
        return np.diag(q ** 2 * self.window_s)

    def stkf(self, x0: np.ndarray, P0: np.ndarray, Q: np.ndarray, model: DriftModel) -> StrongTrackingKF:
        """The default parameter learner; each variance stays below its prior (or P0) in outages."""
        return StrongTrackingKF(x0, P0, Q, fading_s=self.fading_s, adaptive=self.adaptive_fading,
                                reject_sigma=self.reject_sigma, diverged_nis=self.diverged_nis,
                                p_max=np.maximum(np.diag(P0), self.prior_sigma_values(model) ** 2))

    def _from_file(self, model: DriftModel, what: str) -> np.ndarray:
        """Per-term sigmas (`prior_sigmas` or `q_sigmas`): the model file's where it gives them."""
        values = getattr(model, what)()
        f = self.drift_model_file
        if f is not None:
            given = dict(zip(f.names, getattr(f, what)()))
            values = np.array([given.get(n, v) for n, v in zip(model.names, values)])
        return values

    def model(self) -> DriftModel:
        f = self.drift_model_file
        base = tuple(f.names) if f is not None else tuple(self.terms)
        extra = tuple(t for t in SCALE_FACTOR_TERMS if t not in base) if self.scale_factor else ()
        return DriftModel(base + extra, f.temperature_ref_c if f is not None else self.temperature_ref_c)

    def model_inputs(self) -> ModelInputs:
        return self.drift_model_file.model_inputs() if self.drift_model_file is not None else ModelInputs()

    def problems(self) -> list[str]:
        """Why this configuration cannot run, one sentence per problem naming the fields (empty: it
        can). What only the whole config can tell; each number's own range is in the nodes'
        parameter table (nodes/parameters.py)."""
        from .drift_model import BUILTIN_TERMS
        out = []
        terms = tuple(self.terms or ())
        unknown = [t for t in terms if not isinstance(t, Term) and t not in BUILTIN_TERMS]
        names = [t.name if isinstance(t, Term) else t for t in terms] + \
            (list(SCALE_FACTOR_TERMS) if self.scale_factor else [])
        if not terms:
            out.append('terms must name at least one drift-model term')
        elif unknown:
            out.append(f"terms: unknown drift-model term(s) {', '.join(map(repr, unknown))} "
                       f"(known: {', '.join(BUILTIN_TERMS)})")
        elif len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            out.append(f"terms: {', '.join(twice)} given twice"
                       + (' (scale_factor adds rate_temperature and rate)' if self.scale_factor else ''))
        else:
            for key, sigmas in (('prior_sigmas', self.prior_sigmas), ('q_sigmas', self.q_sigmas)):
                if sigmas and len(sigmas) != len(names):
                    out.append(f"{key} has {len(sigmas)} values but the drift model has {len(names)} terms "
                               f"({', '.join(names)})")
        if self.prior_sigmas and not all(np.isfinite(float(v)) and v > 0 for v in self.prior_sigmas):
            out.append('prior_sigmas must all be finite and > 0')
        if self.q_sigmas and not all(np.isfinite(float(v)) and v >= 0 for v in self.q_sigmas):
            out.append('q_sigmas must all be finite and >= 0')
        if not 0 <= self.confirm_s < self.window_s:
            out.append(f'confirm_s = {self.confirm_s:g} must be >= 0 and < window_s = {self.window_s:g}')
        if not 0 <= self.edge_s <= 0.5 * self.window_s:
            out.append(f'edge_s = {self.edge_s:g} must be >= 0 and <= window_s / 2 = {0.5 * self.window_s:g}')
        if not 0 < self.compass_block_s <= self.window_s:
            out.append(f'compass_block_s = {self.compass_block_s:g} must be > 0 and <= window_s = {self.window_s:g}')
        if not self.temperature_min_c < self.temperature_max_c:
            out.append(f'temperature_min_c = {self.temperature_min_c:g} must be < temperature_max_c = '
                       f'{self.temperature_max_c:g}')
        if not self.field_norm_min_t < self.field_range_t:
            out.append(f'field_norm_min_t = {self.field_norm_min_t:g} must be < field_range_t = {self.field_range_t:g}')
        gate = self.gate
        if not 0 < gate.hysteresis <= 1:
            out.append(f'gate.hysteresis = {gate.hysteresis:g} must be a fraction of the threshold in (0, 1]')
        if not gate.mismatch_smooth_s < gate.mismatch_window_s:
            out.append(f'gate.mismatch_smooth_s = {gate.mismatch_smooth_s:g} must be < gate.mismatch_window_s = '
                       f'{gate.mismatch_window_s:g}')
        return out


def gate_for_compass_period(gate: GateConfig, period_s: float | None) -> GateConfig:
    """The gate's settings for a compass sampled every `period_s`: its smoothing of the compass-gyro
    disagreement and its re-learning of the field after a turn hold a few compass samples, and the
    bend window two smoothing spans (sampling.py). At 5 Hz and faster nothing changes."""
    smooth_s = at_least(gate.mismatch_smooth_s, period_s, SMOOTH_SAMPLES)
    return replace(gate, mismatch_smooth_s=smooth_s, mismatch_window_s=max(gate.mismatch_window_s, 2.0 * smooth_s),
                   reference_relearn_s=at_least(gate.reference_relearn_s, period_s, SMOOTH_SAMPLES))
