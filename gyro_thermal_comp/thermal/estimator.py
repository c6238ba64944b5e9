"""`ThermalDriftEstimator`: the STKF thermal-drift heading method (docs/design.md section 2), streaming.

An orchestrator over one component per job (docs/estimator.md has the module table):
  1. `EstimatorInputs` (inputs.py): samples outside the sensors' ranges, bad stamps and stamp jumps
     dropped (every IMU row still gets an output row, holding the last good values, reason
     `dropped_input`); one internal time base across clock jumps; temperature -> local-regression
     T and dT/dt (temperature_rate.py) causally at the IMU stamps, stale when readings stop;
  2. `StillPeriod` (still_period.py): the first seconds give the initial biases and compass noise;
  3. between filter events (window ends, confirmations: every few seconds) the gyro work is
     vectorised (imu_stretch.py): D_hat = H x, compensated rates, heading rate from the tilt,
     integrated gyro heading psi_g;
  4. `CompassBlocks` (compass_blocks.py): compass samples in short blocks through the magnetic gate
     and the heading filter, which corrects the output heading while the gate is open;
  5. `DriftLearning` (drift_learning.py): the drift measurement of every update window steps the
     parameter learner (learner.py) if the gate stayed open; otherwise the estimator COASTS:
     D_hat = H x with the last parameters and the live temperature;
  6. `OutputRows` (output_rows.py): one row per input sample.

Time gaps (IMU stamps further apart than `max_gap_s`): nothing is integrated across the gap, the
heading uncertainty is inflated by `gap_rate_sigma_rad_s` x gap, the drift window containing it is
discarded, the compass-mismatch history is reset, and the sample is flagged `time_gap`. A stale
temperature (`temperature_stale`) keeps the windows from learning and widens the drift uncertainty.
The learned parameters survive everything: they only change through accepted learner steps.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..angles import wrap_angle
from ..heading_track import HeadingTrack
from ..samples import SensorChunk
from .compass import compass_heading
from .coasting import DriftPrediction, InputCoverage
from .compass_blocks import CompassBlocks
from .drift_learning import DriftLearning, LearningSettings
from .estimator_config import EstimatorConfig, gate_for_compass_period
from .heading_filter import HeadingFilter
from .inputs import EstimatorInputs
from .imu_stretch import GyroIntegrator, ImuStretch, context_before_imu, earth_rate_up
from .learner import LearnerFactory, ParameterLearner
from .magnetic_gate import MagneticGate
from .model_state import checked_state
from .output_rows import OutputAssembler, OutputRows, ThermalOutput
from .reasons import REASON_BIT, REASONS, reason_names
from .still_period import StillPeriod, initial_state

__all__ = ['EstimatorConfig', 'ThermalDriftEstimator', 'ThermalOutput', 'REASONS', 'REASON_BIT', 'reason_names']


class ThermalDriftEstimator:
    """STKF thermal-drift heading estimator; implements `HeadingMethod` (`name`, `update`).

    `process(chunk)` returns the richer `ThermalOutput`; `get_state`/`set_state` persist and warm
    start the parameters; `diagnostics()` is a snapshot for a node. `learner(x0, P0, Q)` builds the
    parameter learner when the still period ends (default: the STKF of the config); the baselines
    pass theirs (learner.py)."""

    def __init__(self, config: EstimatorConfig = EstimatorConfig(), learner: LearnerFactory | None = None):
        cfg = config
        if not 0 <= cfg.confirm_s < cfg.window_s:
            raise ValueError('confirm_s must be in [0, window_s)')
        self.cfg = cfg
        self.name = cfg.name
        self.model = cfg.model()
        self.model_inputs = cfg.model_inputs()      # lagged die temperature, branch state (model_inputs.py)
        self.prediction = DriftPrediction(self.model, InputCoverage(cfg.drift_model_file and cfg.drift_model_file.coverage))
        self._arw = math.radians(cfg.arw_deg_sqrt_s)          # the one angle random walk, rad/sqrt(s)
        self._learner_factory = learner or (lambda x0, P0, Q: self._learner_cfg.stkf(x0, P0, Q, self.model))
        self._learner_cfg = cfg                  # the learner's settings (for the compass's rate from the start)
        self._compass_period_s: float | None = None   # measured over the still period, s
        self._warm: dict | None = None
        self.still_use: str | None = None     # what the start did with the still period (still_period.initial_state)
        self.inputs = EstimatorInputs(cfg)
        self._mag_late = 0                                     # compass samples after their block closed
        self.still = StillPeriod(cfg.still_period_s, math.radians(cfg.still_motion_deg),
                                 math.radians(cfg.compass_sigma_floor_deg) ** 2)
        self.gate = MagneticGate(cfg.gate, self._arw, reference_s=cfg.still_period_s)
        self.heading = HeadingFilter(cfg.heading, self._arw)
        # compass blocks tile the update windows exactly
        block_s = cfg.window_s / max(1, round(cfg.window_s / cfg.compass_block_s))
        self.blocks = CompassBlocks(self.gate, self.heading, block_s, cfg.heading_correction, cfg.confirm_s,
                                    cfg.reopen_probation_s)
        self.learning = DriftLearning(LearningSettings(cfg.window_s, cfg.edge_s, cfg.confirm_s, cfg.r_floor_rad_s,
                                                       cfg.innovation_windows, cfg.learn, cfg.adaptive_r),
                                      len(self.model), self.gate.rebase, self.prediction)
        if cfg.coast_backtest:   # what the model's predictions missed weighs its change (coasting.py)
            self.prediction.miss_var = self.learning.backtest.variances_at
        self.gyro = GyroIntegrator(cfg.max_gap_s, cfg.tilt_window_s, math.radians(cfg.gate.turn_rate_deg_s),
                                   earth_rate_up(cfg.latitude_deg))
        self.output = OutputAssembler(cfg.mag_timeout_s)
        self._compass_var = math.radians(cfg.compass_sigma_deg or cfg.compass_sigma_default_deg) ** 2
        # integration state
        self.t_origin: float | None = None    # grid of windows and blocks, start of the still period
        self._started = False
        self._mag_waiting = (np.empty(0), np.empty((0, 3)))   # compass before the first IMU sample
        self._bias_xy = np.zeros(2)
        self._time_gaps = 0
        self._coast_sigma_d = (0.0, 0.0)   # largest drift sigmas since the last compass correction, rad/s
        self._sigma_record_t = -math.inf   # time of that correction, s
        self._backtest_var = 0.0           # what past predictions of the live age missed beyond P, (rad/s)^2

    # ------------------------------------------------------------------ persistence / warm start
    def get_state(self) -> dict:
        """Parameters and covariance (plain data) with the model they belong to."""
        st = {'terms': list(self.model.names), 'temperature_ref_c': self.model.temperature_ref_c}
        if self.prediction.coverage.temp is not None:   # what the learned parameters have seen
            st['coverage'] = self.prediction.coverage.to_dict()
        if self.learner is not None:
            st.update({'x': self.learner.x.tolist(), 'P': self.learner.P.tolist()})
        elif self._warm is not None:
            st.update(self._warm)
        heading = self.heading.learned() or self.heading.carried   # the vehicle's compass deviation, scale factor
        if heading is not None:
            st['heading'] = heading
        return st

    def set_state(self, state: dict) -> None:
        """Before the still period ends: warm start (the parameters and their covariance are kept,
        and the still period's drift measurement is combined with them, still_period.initial_state;
        a `heading` map of the heading filter carries over). After: replaces the running
        parameters. A state that does not fit this model, or is implausible, raises ValueError
        (model_state.py)."""
        x, P = checked_state(state, self.model, self.cfg)
        coverage = InputCoverage(state['coverage']) if state.get('coverage') else None   # ValueError before any change
        if state.get('heading') is not None and not self.heading.initialized:
            self.heading.carry_over(state['heading'])
        if coverage is not None:
            coverage.memory_s = self.prediction.coverage.memory_s
            self.prediction.coverage = coverage
        if self.learner is not None:
            self.learner.set_state(x, P)
            self.learning.update_sigma_d(self._live_row())
        else:
            self._warm = {'x': x.tolist(), 'P': None if P is None else P.tolist()}

    def set_gate_config(self, **changes) -> None:
        """Change gate thresholds at run time (names of `GateConfig`); everything derived from them
        follows, here and in the gate. An unknown name raises TypeError and changes nothing."""
        self.cfg = replace(self.cfg, gate=replace(self.cfg.gate, **changes))
        config = gate_for_compass_period(self.cfg.gate, self._compass_period_s)
        self.gate.set_config(config)
        self.gyro.tilt_max_rate_rad_s = math.radians(config.turn_rate_deg_s)

    @property
    def learner(self) -> ParameterLearner | None:
        return self.learning.learner

    @property
    def params(self) -> np.ndarray:
        """Drift-model parameters in force (SI units, order of `model.names`); before the still period
        ends, those of a warm start (its `constant` is re-measured there) or zeros."""
        if self.learner is not None:
            return self.learner.x
        return np.asarray(self._warm['x'], dtype=float) if self._warm is not None else np.zeros(len(self.model))

    def _param_sigmas(self) -> np.ndarray:
        if self.learner is None:
            return np.full(len(self.model), np.nan)
        return np.sqrt(np.maximum(self.learner.P.diagonal(), 0.0))

    # ------------------------------------------------------------------ HeadingMethod
    def update(self, chunk: SensorChunk) -> HeadingTrack:
        return self.process(chunk).track

    def process(self, chunk: SensorChunk) -> ThermalOutput:
        """Consume one chunk (time order); one output row per `chunk.imu` sample."""
        accepted = self.inputs.accept(chunk)
        t_imu, gyro, acc = accepted.t_imu, accepted.gyro, accepted.accel
        # compass samples whose block was already processed: a prefix (kept stamps increase)
        n_late = int(accepted.t_mag.searchsorted(self.blocks.closed_until, side='left'))
        self._mag_late += n_late
        t_mag, field = accepted.t_mag[n_late:], accepted.field[n_late:]
        if self.t_origin is None and (t_imu.size or t_mag.size):
            self.t_origin = float(min(t_imu[0] if t_imu.size else np.inf, t_mag[0] if t_mag.size else np.inf))
            self.still.begin(self.t_origin)
            self.blocks.t_origin = self.t_origin
        temperature = self.inputs.temperature_at(chunk.temperature, t_imu)
        temp_c, temp_rate, temp_ok = temperature.temp_c, temperature.rate_c_s, temperature.known
        parts = []
        i = j = 0
        while i < t_imu.size or j < t_mag.size:
            tick = self._next_tick()
            # (stamps increase: the same as searching from i and j on)
            i_end = max(i, int(t_imu.searchsorted(tick, side='left')))
            j_end = max(j, int(t_mag.searchsorted(tick, side='left')))
            if i_end > i or j_end > j:
                stop = self._still_motion(t_imu[i:i_end], gyro[i:i_end], acc[i:i_end]) \
                    if not self._started and i_end > i else None
                if stop is not None:   # the unit moved: the still period ends at sample `stop`
                    i_end = i + stop + 1
                    tick = self.still.end_s = float(t_imu[i_end - 1])
                    j_end = j + int(np.searchsorted(t_mag[j:j_end], tick, side='left'))
                rows = self._stretch(t_imu[i:i_end], gyro[i:i_end], acc[i:i_end], temp_c[i:i_end],
                                     temp_rate[i:i_end], temp_ok[i:i_end], t_mag[j:j_end], field[j:j_end])
                if rows is not None:
                    parts.append(rows)
                i, j = i_end, j_end
            if i < t_imu.size or j < t_mag.size:
                self.blocks.close(tick, *self._drift_sigmas(), self._compass_var)
                self._on_tick(tick)
        mag_t = np.concatenate(([accepted.t_mag_before], t_mag))
        mag_period = np.concatenate(([accepted.mag_period_before], accepted.mag_period[n_late:]))
        last_mag = np.maximum(mag_t.searchsorted(t_imu, side='right') - 1, 0)
        return self.output.assemble(parts, accepted.imu_ok, None if chunk.imu is None else chunk.imu.t, t_imu,
                                    mag_t[last_mag], self.still.end_s, self.inputs.temp.stuck, self.params,
                                    self._param_sigmas(), self.inputs.temp.guard.first_t, mag_period[last_mag])

    # ------------------------------------------------------------------ filter events
    def _next_tick(self) -> float:
        if self.t_origin is None:
            return np.inf
        return self.learning.next_tick() if self._started else self.still.end_s

    def _on_tick(self, tick: float) -> None:
        if not self._started:
            self._start(tick)
        else:
            self.learning.fire(tick, self._arw, self._compass_var, self.blocks.t_last_closed, self._live_row())
            # the coasting variance at the live inputs, at a stamp the record decides (not the chunking)
            self.prediction.refresh(self._live_inputs(), self.params, self.learner.P, tick)
            backtest = self.learning.backtest
            self._backtest_var = backtest.variance_at(tick - backtest.t_update) if self.cfg.coast_backtest else 0.0

    def _drift_sigmas(self) -> tuple[float, float]:
        """1-sigma of D_hat now, rad/s, for the heading uncertainty (eq. 13), as (the model's own
        account, for the gate; plus what past predictions of this age missed beyond it, backtest.py,
        and the change it foresaw but did not follow, coasting.py, for the heading filter and the
        published sigma). The gate keeps the first: a wider allowance lets a slow disturbance back in
        (on a family-B outage it reopened inside a 27 deg rotation).
        Both widened while the temperature is stale, and never smaller than since the last compass
        correction (a learner step may shrink sigma_d, but not the error of a heading nothing has
        measured since)."""
        pred = self.prediction
        learned = self.learning.sigma_d ** 2 + pred.var_change + pred.var_beyond
        sigmas = (math.sqrt(learned), math.sqrt(learned + self._backtest_var + pred.var_unfollowed))
        if self.gyro.latest is not None:
            sigmas = tuple(self.inputs.drift_sigma(s, self.gyro.t_last, self.gyro.temp_last, self.model, self.params)
                           for s in sigmas)
        latest = self.blocks.latest
        if latest.open[0] and latest.t[0] != self._sigma_record_t:   # a compass correction since
            self._sigma_record_t = float(latest.t[0])
        else:
            sigmas = tuple(max(s, c) for s, c in zip(sigmas, self._coast_sigma_d))
        self._coast_sigma_d = sigmas
        return sigmas

    def _live_inputs(self) -> dict:
        """The live model inputs (temperature, its rate, branch...; no turn), one row."""
        last = self.model_inputs.last
        if last is None:
            return self.model.neutral_inputs(self.model.temperature_ref_c)
        return {**{k: np.array([v]) for k, v in last.items()}, 'rate': np.zeros(1)}

    def _live_row(self) -> np.ndarray:
        """Regressor row at the live model inputs."""
        return self.model.rows(self._live_inputs())[0]

    def _start(self, t_start: float) -> None:
        """End of the still period: the settings for the compass's measured rate, biases, initial
        parameters and learner, compass noise, the gyro noise the stream carries."""
        self._compass_period_s = self.inputs.mag_period.period_s
        cfg = self.cfg.for_compass_period(self._compass_period_s)   # the settings in force from now on
        self.learning.settings = replace(self.learning.settings, window_s=cfg.window_s, edge_s=cfg.edge_s)
        self.gate.set_config(cfg.gate)
        self._learner_cfg = cfg
        self.prediction.coverage.memory_s = cfg.memory_s()
        still = self.still.finish(self._arw, cfg.r_floor_rad_s)
        self._take_noise(still)
        self._bias_xy = still.mean_rates_rad_s[:2].copy()
        t0 = still.temperature_c if still.temperature_c is not None else self.inputs.temp_fallback_c
        if cfg.compass_sigma_deg is None and still.compass_var_rad2 is not None and not still.cut_short:
            self._compass_var = still.compass_var_rad2
        warm = self._warm
        if warm is None and cfg.drift_model_file is not None:   # the file's starting values, as a warm start
            priors = cfg.drift_model_file.priors()
            warm = {'x': [priors.get(n, 0.0) for n in self.model.names], 'P': None}
        x0, P0, self.still_use = initial_state(self.model, still, t0, cfg.prior_sigma_values(self.model), warm,
                                               cfg.reject_sigma)
        learner = self._learner_factory(x0, P0, cfg.q_matrix(self.model))
        self._started = True
        self.learning.start(learner, t_start, self.t_origin, self._live_row())
        if still.cut_short or self.still_use == 'refused':
            # the unit moved: the gyro heading integrated with the running mean as its drift, and
            # the compass levelled by a tilt taken on the move, are no heading: unknown, as after
            # a time gap, until the gate passes the compass
            self.blocks.on_gap(math.pi ** 2)

    def _take_noise(self, still) -> None:
        """The angle random walk in force: the configured one (the sensor's noise density), or what
        the still period measured where that is significantly larger (still_period.py): the stream
        carries more noise than the sensor's density (point sampling, vibration), and R, the gate's
        allowances and the heading sigma must know it."""
        if still.arw_rad_sqrt_s is not None and still.arw_rad_sqrt_s != self._arw:
            self._arw = still.arw_rad_sqrt_s
            self.gate.arw_rad_sqrt_s = self._arw
            self.heading.arw_rad_sqrt_s = self._arw

    @property
    def arw_rad_sqrt_s(self) -> float:
        """The angle random walk in force, rad/sqrt(s)."""
        return self._arw

    @property
    def tilt_max_rate_rad_s(self) -> float:
        """Turn rate above which a sample stays out of the roll and pitch (centripetal force), rad/s."""
        return self.gyro.tilt_max_rate_rad_s

    @property
    def still_end_s(self) -> float | None:
        """Stamp at which the still period ends, s (earlier if the unit moved); None before any sample."""
        return self.still.end_s

    @property
    def still_left_s(self) -> float | None:
        """Stamp time left in the still period after the newest IMU sample, s (negative once it is
        over); None before any sample."""
        if self.t_origin is None or self.still.end_s is None:
            return None
        return self.still.end_s - max(self.gyro.t_last, self.t_origin)

    @property
    def imu_span_s(self) -> float:
        """Stamp span of the IMU samples integrated so far, from the first sample, s (0 before any)."""
        return self.gyro.t_last - self.t_origin if self.t_origin is not None else 0.0

    @property
    def drift_window_s(self) -> float:
        """The drift window in force, s: the configured one until the still period ends, then the
        one sized for the compass's measured rate (estimator_config.for_compass_period)."""
        return self._learner_cfg.window_s

    # ------------------------------------------------------------------ vectorised stretch
    def _still_motion(self, t, gyro, acc) -> int | None:
        """Index of the first sample whose gyro heading left the start by `still_motion_deg`."""
        d_hat, bias_xy = self.still.running_mean(gyro)
        return self.still.first_motion(t, self.gyro.probe_heading(t, gyro, acc, d_hat, bias_xy))

    def _stretch(self, t, gyro, acc, temp_c, temp_rate, temp_ok, t_mag, field) -> OutputRows | None:
        """IMU then compass samples of one stretch with fixed parameters; its output rows."""
        stretch = None
        before = self.gyro.latest  # its last row: the IMU state before this stretch (for its compass samples)
        if t.size:
            stretch, response = self._integrate(t, gyro, acc, temp_c, temp_rate, temp_ok)
        if t_mag.size or (stretch is not None and self._mag_waiting[0].size):
            self._compass(t_mag, field, stretch, before)
        t_seen = max(self.gyro.t_last if stretch is not None else -np.inf,
                     float(t_mag[-1]) if t_mag.size else -np.inf)
        self.blocks.close(t_seen, *self._drift_sigmas(), self._compass_var)
        if stretch is None:
            return None
        heading = self.blocks.heading_at(stretch.t, stretch.psi_g, self._arw, self._drift_sigmas()[1])
        return OutputRows.of_stretch(stretch, heading, *response)

    def _integrate(self, t, gyro, acc, temp_c, temp_rate, temp_ok):
        """D_hat = H x (docs/design.md eq. 5), its change since the last update weighed as coasting.py
        weighs it, then the gyro work of imu_stretch.py. Returns the stretch and, per row, the
        drift's response to the turn rate (1) and its trend (rad/s^2) for the fast path."""
        inputs = self.model_inputs.at(t, temp_c, temp_rate, temp_ok, gyro[:, 2])
        H = self.model.rows(inputs)
        learning = self.learning
        x = self.params
        if self._started:
            d_hat, kappa = self.prediction.predict(H, inputs, x, self.learner.P, t)
            bias_xy = self._bias_xy
            k_rate, trend = self.model.response(x, inputs)
            response = (k_rate, kappa * trend)
            learning.note_inputs(inputs['temperature'], inputs['temperature_rate'])
        else:  # the still period: its running mean is the drift estimate
            d_hat, bias_xy = self.still.running_mean(gyro)
            response = (np.zeros(t.size), np.zeros(t.size))
        window_t0 = None if learning.window is None else learning.window.t0
        stretch, gap_s = self.gyro.integrate(t, gyro, acc, d_hat, bias_xy, H, temp_c, temp_rate, temp_ok,
                                             x, window_t0, learning.i_d, learning.i_h)
        if not self._started:
            self.still.add_imu(t, gyro, temp_c, temp_ok, stretch.psi_g)
        if gap_s is not None:
            self._time_gaps += int(np.count_nonzero(stretch.gap))
            learning.t_last_gap = float(t[stretch.gap][-1])
            # nothing was integrated over the gap: the next compass correction is taken at once
            self.blocks.on_gap(min((self.cfg.gap_rate_sigma_rad_s * gap_s) ** 2, math.pi ** 2))
        if not temp_ok.all():
            stale = ~temp_ok & (t >= self.inputs.temp.guard.first_t)   # readings came, then stopped
            if np.any(stale):   # no learning from a window with a stale temperature
                learning.t_last_untrusted = float(t[stale][-1])
        learning.i_d, learning.i_h = float(stretch.i_d[-1]), stretch.i_h[-1].copy()
        return stretch, response

    def _compass(self, t_mag, field, stretch: ImuStretch | None, before: ImuStretch | None) -> None:
        """Per compass sample: gyro state there, compass heading, window and block bookkeeping.
        `before`: the stretch before (its last row is the IMU state before `stretch`). Compass
        samples before any IMU sample wait for the first one and take the start of the
        integration (psi_g = 0) with its gravity."""
        if before is None and stretch is None:
            self._mag_waiting = (np.concatenate((self._mag_waiting[0], t_mag)),
                                 np.concatenate((self._mag_waiting[1], field)))
            return
        if before is None:
            t_mag = np.concatenate((self._mag_waiting[0], t_mag))
            field = np.concatenate((self._mag_waiting[1], field))
            self._mag_waiting = (np.empty(0), np.empty((0, 3)))
            # at or before the first IMU sample: the start of the integration, its gravity
            before = replace(stretch.row(0), t=t_mag[:1].copy(), rate=np.zeros(1))
        ctx = stretch.at_stamps(t_mag, before) if stretch is not None else context_before_imu(before, t_mag)
        i_d, i_h = self.learning.integrals_from_window_start(t_mag, ctx)
        reading = compass_heading(field, None, self.cfg.declination_rad, roll_pitch=(ctx.roll, ctx.pitch))
        psi_c = np.atleast_1d(reading.heading_rad)
        self.learning.add_compass(t_mag, ctx.psi_g + i_d - psi_c, i_h)
        z = np.atleast_1d(wrap_angle(psi_c - ctx.psi_g))
        if not self._started:
            self.still.add_compass(t_mag, z)
        self.blocks.add(t_mag, z, ctx.psi_g, psi_c, reading.field_norm_t, reading.dip_rad, ctx.accel, ctx.temp,
                        self._compass_var)

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self) -> dict:
        """Snapshot for a node's diagnostics: parameters, sigmas, gate, counters."""
        # the latest output row carries the estimator's reasons too (no compass, gap, stale temperature)
        latest = self.output.latest or self.blocks.latest
        d = {'started': self._started, 'params': self.model.paper_coefficients(self.params),
             'param_sigmas': dict(zip(self.model.names, self._param_sigmas().tolist())),
             'drift_sigma_rad_s': max(self._coast_sigma_d[1], self.learning.sigma_d),   # (no side effect)
             'drift_change_weight': self.prediction.kappa, 'input_coverage': self.prediction.coverage.to_dict(),
             'window_r_scale': self.learning.r_scale, 'drift_backtest_sigma_rad_s': math.sqrt(self._backtest_var),
             'temperature_age_s': self.inputs.age_s(self.gyro.t_last),
             'gate_open': bool(latest.open[0]), 'gate_reasons': reason_names(latest.reasons[0]),
             'coasting_for_s': float(self.heading.tau_coast), 'heading_sigma_rad': self.heading.sigma_rad,
             'temperature_stuck': self.inputs.temp.stuck, 'temperature_stuck_for_s': self.inputs.temp.stuck_for_s(),
             'compass_sigma_rad': math.sqrt(self._compass_var),
             'gate_reference': {'field_norm_t': self.gate.ref_norm, 'dip_rad': self.gate.ref_dip,
                                'accel_norm_m_s2': self.gate.reference.at('accel_norm', math.nan),
                                'slopes_per_c': self.gate.reference.slopes(),
                                'noise_sigma': self.gate.reference.noise_sigmas()},
             'arw_deg_sqrt_s': math.degrees(self._arw), 'compass_period_s': self._compass_period_s,
             'window_s': self.drift_window_s,
             'coasting_s': self.blocks.coasting_s, **self.counters()}
        return d

    def counters(self) -> dict[str, int]:
        """Event counts since construction: dropped inputs by stream and reason, gaps, windows."""
        c = {**self.inputs.counters(), 'mag_dropped_late': self._mag_late, 'time_gaps': self._time_gaps,
             'heading_rollbacks': self.blocks.rollbacks,
             'heading_probation_rollbacks': self.blocks.probation_rollbacks,
             'gate_drift_lines': self.gate.n_drift_lines,
             **{f'gate_reference_refits_{k}': v for k, v in self.gate.reference.refits.items()},
             **self.learning.counters}
        if self.learner is not None:
            c['filter_updates'] = self.learner.n_updates
            c['filter_rejected'] = self.learner.n_rejected
            c['filter_resets'] = self.learner.n_resets
        return c

