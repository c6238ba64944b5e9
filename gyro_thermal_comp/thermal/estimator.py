"""`ThermalDriftEstimator`: the STKF thermal-drift heading method (docs/design.md section 2), streaming.

An orchestrator over one component per job (docs/estimator.md has the module table):
  1. `EstimatorInputs` (inputs.py): samples outside the sensors' ranges, bad stamps and stamp jumps
     dropped (every IMU row still gets an output row, holding the last good values, reason
     `dropped_input`); one internal time base across clock jumps; temperature -> local-regression
     T and dT/dt (temperature_rate.py) causally at the IMU stamps, stale when readings stop;
  2. `StillPeriod` (still_period.py): the first seconds give the initial biases and compass noise;
     `StartUp` (start_up.py) ends the period (at its length, or when the unit moves) and fixes the
     settings for the compass's rate, the noise in force, the initial parameters and the learner;
  3. between filter events (window ends, confirmations: every few seconds) the gyro work is
     vectorised (imu_stretch.py): D_hat = H x, compensated rates, heading rate from the tilt,
     integrated gyro heading psi_g;
  4. `CompassIntake` (compass_intake.py): each compass sample's heading against the gyro state
     there; `CompassBlocks` (compass_blocks.py): those in short blocks through the magnetic gate
     and the heading filter, which corrects the output heading while the gate is open;
  5. `DriftLearning` (drift_learning.py): the drift measurement of every update window steps the
     parameter learner (learner.py) if the gate stayed open; otherwise the estimator COASTS:
     D_hat = H x with the last parameters and the live temperature;
  6. `DriftSigma` (drift_sigma.py): the drift 1-sigma the gate and the heading uncertainty use;
  7. `OutputRows` (output_rows.py): one row per input sample;
  8. `ParameterState` (parameter_state.py): the parameters in force and their state as plain data
     (`get_state`/`set_state`, warm start); diagnostics.py: the node's diagnostics and counters.

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

from ..heading_track import HeadingTrack
from ..samples import SensorChunk
from .coasting import DriftPrediction, InputCoverage
from .compass_blocks import CompassBlocks
from .compass_intake import CompassIntake
from .diagnostics import estimator_counters, estimator_diagnostics
from .drift_learning import DriftLearning, LearningSettings
from .drift_sigma import DriftSigma
from .estimator_config import EstimatorConfig, gate_for_compass_period
from .heading_filter import HeadingFilter
from .inputs import EstimatorInputs
from .imu_stretch import GyroIntegrator, earth_rate_up
from .learner import LearnerFactory, ParameterLearner
from .magnetic_gate import MagneticGate
from .output_rows import OutputAssembler, OutputRows, ThermalOutput
from .parameter_state import ParameterState
from .reasons import REASON_BIT, REASONS, reason_names
from .start_up import StartUp
from .still_period import StillPeriod

__all__ = ['EstimatorConfig', 'ThermalDriftEstimator', 'ThermalOutput', 'REASONS', 'REASON_BIT', 'reason_names']


class ThermalDriftEstimator:
    """STKF thermal-drift heading estimator; implements `HeadingMethod` (`name`, `update`).

    `process(chunk)` returns the richer `ThermalOutput`; `get_state`/`set_state` persist and warm
    start the parameters (parameter_state.py); `diagnostics()` is a snapshot for a node
    (diagnostics.py). `learner(x0, P0, Q)` builds the parameter learner when the still period ends
    (start_up.py; default: the STKF of the config); the baselines pass theirs (learner.py).
    `guards`: the input streams' guards, shared with a pipeline that applies them as samples come
    in and then gives `process` chunks with `admitted` (inputs.py); None: the estimator's own."""

    def __init__(self, config: EstimatorConfig = EstimatorConfig(), learner: LearnerFactory | None = None,
                 guards: dict | None = None):
        cfg = config
        if not 0 <= cfg.confirm_s < cfg.window_s:
            raise ValueError('confirm_s must be in [0, window_s)')
        self.cfg = cfg
        self.name = cfg.name
        self.model = cfg.model()
        self.model_inputs = cfg.model_inputs()      # lagged die temperature, branch state (model_inputs.py)
        coverage = InputCoverage(cfg.drift_model_file and cfg.drift_model_file.coverage)   # what a model file covered
        self.prediction = DriftPrediction(self.model, coverage)
        arw = cfg.arw_rad_sqrt_s                   # the configured angle random walk, rad/sqrt(s)
        self.inputs = EstimatorInputs(cfg, guards)
        self.still = StillPeriod(cfg.still_period_s, cfg.still_motion_rad,
                                 cfg.compass_sigma_floor_rad ** 2)
        self.gate = MagneticGate(cfg.gate, arw, reference_s=cfg.still_period_s)
        self.heading = HeadingFilter(cfg.heading, arw)
        # compass blocks tile the update windows exactly
        block_s = cfg.window_s / max(1, round(cfg.window_s / cfg.compass_block_s))
        self.blocks = CompassBlocks(self.gate, self.heading, block_s, cfg.heading_correction, cfg.confirm_s,
                                    cfg.reopen_probation_s)
        self.learning = DriftLearning(LearningSettings(cfg.window_s, cfg.edge_s, cfg.confirm_s, cfg.r_floor_rad_s,
                                                       cfg.innovation_windows, cfg.learn, cfg.adaptive_r),
                                      len(self.model), self.gate.rebase, self.prediction)
        if cfg.coast_backtest:   # what the model's predictions missed weighs its change (coasting.py)
            self.prediction.miss_var = self.learning.backtest.variances_at
        self.gyro = GyroIntegrator(cfg.max_gap_s, cfg.tilt_window_s, cfg.gate.turn_rate_rad_s,
                                   earth_rate_up(cfg.latitude_deg))
        self.output = OutputAssembler(cfg.mag_timeout_s)
        self.startup = StartUp(cfg, self.model, learner, self.still, self.inputs, self.gate, self.heading,
                               self.blocks, self.learning, self.prediction)
        self.param_state = ParameterState(self.model, self.prediction, self.learning, self.heading)
        self.drift_sigma = DriftSigma(self.prediction)   # 1-sigma of D_hat for the gate and the heading
        self.compass = CompassIntake(cfg.declination_rad, self.learning, self.still, self.blocks, self.startup)
        self.t_origin: float | None = None    # grid of windows and blocks, start of the still period
        self.mag_dropped_late = self.time_gaps = 0   # compass samples after their block closed; time gaps

    # ------------------------------------------------------------------ persistence / warm start
    def get_state(self) -> dict:
        """Parameters and covariance (plain data) with the model they belong to."""
        return self.param_state.get()

    def set_state(self, state: dict) -> None:
        """Before the still period ends: warm start; after: replaces the running parameters (parameter_state.py).
        A state that does not fit this model, or is implausible, raises ValueError (model_state.py)."""
        self.param_state.set(state, self.cfg, self._live_row)

    def set_gate_config(self, **changes) -> None:
        """Change gate thresholds at run time (names of `GateConfig`); everything derived from them
        follows, here and in the gate. An unknown name raises TypeError and changes nothing."""
        self.cfg = replace(self.cfg, gate=replace(self.cfg.gate, **changes))
        config = gate_for_compass_period(self.cfg.gate, self.startup.compass_period_s)
        self.gate.set_config(config)
        self.gyro.tilt_max_rate_rad_s = config.turn_rate_rad_s

    @property
    def learner(self) -> ParameterLearner | None:
        return self.learning.learner

    @property
    def params(self) -> np.ndarray:
        """Drift-model parameters in force, SI units, order of `model.names` (parameter_state.py)."""
        return self.param_state.params()

    @property
    def still_use(self) -> str | None:
        """What the start did with the still period (still_period.initial_state); None before."""
        return self.startup.still_use

    @property
    def arw_rad_sqrt_s(self) -> float:
        """The angle random walk in force, rad/sqrt(s)."""
        return self.startup.arw_rad_sqrt_s

    @property
    def drift_window_s(self) -> float:
        """The drift window in force, s: the configured one until the still period ends, then the
        one sized for the compass's measured rate (estimator_config.for_compass_period)."""
        return self.startup.settings.window_s

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
        """Still period left after the newest IMU sample, s (negative once over); None before any sample."""
        return None if self.t_origin is None or self.still.end_s is None else \
            self.still.end_s - max(self.gyro.t_last, self.t_origin)

    @property
    def imu_span_s(self) -> float:
        """Stamp span of the IMU samples integrated so far, s (0 before any)."""
        return self.gyro.t_last - self.t_origin if self.t_origin is not None else 0.0

    # ------------------------------------------------------------------ HeadingMethod
    def update(self, chunk: SensorChunk) -> HeadingTrack:
        return self.process(chunk).track

    def process(self, chunk: SensorChunk, admitted: bool = False) -> ThermalOutput:
        """Consume one chunk (time order); one output row per `chunk.imu` sample. `admitted`: every
        sample already passed the input guards (a pipeline's; they are not applied again)."""
        accepted = self.inputs.accept(chunk, admitted)
        t_imu, gyro, acc = accepted.t_imu, accepted.gyro, accepted.accel
        # compass samples whose block was already processed: a prefix (kept stamps increase)
        n_late = int(accepted.t_mag.searchsorted(self.blocks.closed_until, side='left'))
        self.mag_dropped_late += n_late
        t_mag, field = accepted.t_mag[n_late:], accepted.field[n_late:]
        if self.t_origin is None and (t_imu.size or t_mag.size):
            self.t_origin = float(min(t_imu[0] if t_imu.size else np.inf, t_mag[0] if t_mag.size else np.inf))
            self.still.begin(self.t_origin)
            self.blocks.t_origin = self.t_origin
        temperature = self.inputs.temperature_at(chunk.temperature, t_imu, admitted)
        temp_c, temp_rate, temp_ok = temperature.temp_c, temperature.rate_c_s, temperature.known
        parts = []
        i = j = 0
        while i < t_imu.size or j < t_mag.size:
            tick = self._next_tick()
            # (stamps increase: the same as searching from i and j on)
            i_end = max(i, int(t_imu.searchsorted(tick, side='left')))
            j_end = max(j, int(t_mag.searchsorted(tick, side='left')))
            if i_end > i or j_end > j:
                stop = self.startup.first_motion(t_imu[i:i_end], gyro[i:i_end], acc[i:i_end], self.gyro) \
                    if not self.startup.started and i_end > i else None
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
                self.blocks.close(tick, *self._drift_sigmas(), self.startup.compass_var_rad2)
                self._on_tick(tick)
        mag_t = np.concatenate(([accepted.t_mag_before], t_mag))
        mag_period = np.concatenate(([accepted.mag_period_before], accepted.mag_period[n_late:]))
        last_mag = np.maximum(mag_t.searchsorted(t_imu, side='right') - 1, 0)
        return self.output.assemble(parts, accepted.imu_ok, None if chunk.imu is None else chunk.imu.t, t_imu,
                                    mag_t[last_mag], self.still.end_s, self.inputs.temp.stuck, self.params,
                                    self.param_state.sigmas(), self.inputs.temp.first_t, mag_period[last_mag])

    # ------------------------------------------------------------------ filter events
    def _next_tick(self) -> float:
        if self.t_origin is None:
            return np.inf
        return self.learning.next_tick() if self.startup.started else self.still.end_s

    def _on_tick(self, tick: float) -> None:
        start = self.startup
        if not start.started:
            start.finish(tick, self.cfg, self.t_origin, self.param_state.starting_values(self.cfg.drift_model_file),
                         self._live_row())
        else:
            self.learning.fire(tick, start.arw_rad_sqrt_s, start.compass_var_rad2, self.blocks.t_last_closed,
                               self._live_row())
            # the coasting variance at the live inputs, at a stamp the record decides (not the chunking)
            self.prediction.refresh(self.model_inputs.live(self.model), self.params, self.learner.P, tick)
            self.drift_sigma.refresh(tick, self.learning.backtest if self.cfg.coast_backtest else None)

    def _drift_sigmas(self) -> tuple[float, float]:
        """1-sigma of D_hat now for the gate and the heading, rad/s (drift_sigma.py; stale temperature: inputs.py)."""
        gyro = self.gyro
        widen = None if gyro.latest is None else \
            (lambda s: self.inputs.drift_sigma(s, gyro.t_last, gyro.temp_last, self.model, self.params))
        return self.drift_sigma.now(self.learning.sigma_d, self.blocks.latest, widen)

    def _live_row(self) -> np.ndarray:
        """Regressor row at the live model inputs."""
        return self.model.rows(self.model_inputs.live(self.model))[0]

    # ------------------------------------------------------------------ vectorised stretch
    def _stretch(self, t, gyro, acc, temp_c, temp_rate, temp_ok, t_mag, field) -> OutputRows | None:
        """IMU then compass samples of one stretch with fixed parameters; its output rows."""
        stretch = None
        before = self.gyro.latest  # its last row: the IMU state before this stretch (for its compass samples)
        if t.size:
            stretch, response = self._integrate(t, gyro, acc, temp_c, temp_rate, temp_ok)
        if t_mag.size or (stretch is not None and self.compass.waiting):
            self.compass.take(t_mag, field, stretch, before)
        t_seen = max(self.gyro.t_last if stretch is not None else -np.inf,
                     float(t_mag[-1]) if t_mag.size else -np.inf)
        self.blocks.close(t_seen, *self._drift_sigmas(), self.startup.compass_var_rad2)
        if stretch is None:
            return None
        heading = self.blocks.heading_at(stretch.t, stretch.psi_g, self.startup.arw_rad_sqrt_s,
                                         self._drift_sigmas()[1])
        return OutputRows.of_stretch(stretch, heading, *response)

    def _integrate(self, t, gyro, acc, temp_c, temp_rate, temp_ok):
        """D_hat = H x (docs/design.md eq. 5), its change since the last update weighed as coasting.py
        weighs it, then the gyro work of imu_stretch.py. Returns the stretch and, per row, the
        drift's response to the turn rate (1) and its trend (rad/s^2) for the fast path."""
        inputs = self.model_inputs.at(t, temp_c, temp_rate, temp_ok, gyro[:, 2])
        H = self.model.rows(inputs)
        learning = self.learning
        x = self.params
        if self.startup.started:
            d_hat, kappa = self.prediction.predict(H, inputs, x, self.learner.P, t)
            bias_xy = self.startup.bias_xy
            k_rate, trend = self.model.response(x, inputs)
            response = (k_rate, kappa * trend)
            learning.note_inputs(inputs['temperature'], inputs['temperature_rate'])
        else:  # the still period: its running mean is the drift estimate
            d_hat, bias_xy = self.still.running_mean(gyro)
            response = (np.zeros(t.size), np.zeros(t.size))
        window_t0 = None if learning.window is None else learning.window.t0
        stretch, gap_s = self.gyro.integrate(t, gyro, acc, d_hat, bias_xy, H, temp_c, temp_rate, temp_ok,
                                             x, window_t0, learning.i_d, learning.i_h)
        if not self.startup.started:
            self.still.add_imu(t, gyro, temp_c, temp_ok, stretch.psi_g)
        if gap_s is not None:
            self.time_gaps += int(np.count_nonzero(stretch.gap))
            learning.t_last_gap = float(t[stretch.gap][-1])
            # nothing was integrated over the gap: the next compass correction is taken at once
            self.blocks.on_gap(min((self.cfg.gap_rate_sigma_rad_s * gap_s) ** 2, math.pi ** 2))
        if not temp_ok.all():
            stale = ~temp_ok & (t >= self.inputs.temp.first_t)   # readings came, then stopped
            if np.any(stale):   # no learning from a window with a stale temperature
                learning.t_last_untrusted = float(t[stale][-1])
        learning.i_d, learning.i_h = float(stretch.i_d[-1]), stretch.i_h[-1].copy()
        return stretch, response

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self) -> dict:
        """Snapshot for a node's diagnostics: parameters, sigmas, gate, counters (diagnostics.py)."""
        return estimator_diagnostics(self)

    def counters(self) -> dict[str, int]:
        """Event counts since construction: dropped inputs by stream and reason, gaps, windows."""
        return estimator_counters(self)
