"""`StartUp`: the end of the still period and what it fixes for the rest of the run.

While the unit holds still (still_period.py) the estimator runs on the configured settings and the
gyro's running mean. The still period ends at its planned length, or earlier at the first IMU sample
whose gyro heading, integrated with that running mean as the drift, left its start by
`still_motion_rad` (`first_motion`). Its end (`finish`) fixes:
  - the settings for the compass's measured rate (estimator_config.for_compass_period): drift
    window, edges, the gate's averaging spans, the learner's memory;
  - the noise in force: the angle random walk the stream carries where it is significantly more
    than the sensor's density (point sampling, vibration: R, the gate's allowances and the heading
    sigma must know it), and the compass noise from the compass's scatter about a line;
  - the x/y gyro biases (their mean rates);
  - the initial parameters and covariance (still_period.initial_state, from a warm start or the
    model file's starting values where there are), and the parameter learner built on them.
A period cut short by motion, or whose drift measurement a warm start refused, leaves no heading:
the gyro heading integrated a turn as drift and the compass was levelled by a tilt taken on the
move, so the heading is unknown, as after a time gap, until the gate passes the compass.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .coasting import DriftPrediction
from .compass_blocks import CompassBlocks
from .drift_learning import DriftLearning
from .drift_model import DriftModel
from .estimator_config import EstimatorConfig
from .heading_filter import HeadingFilter
from .imu_stretch import GyroIntegrator
from .inputs import EstimatorInputs
from .learner import LearnerFactory
from .magnetic_gate import MagneticGate
from .still_period import StillPeriod, StillResult, initial_state


class StartUp:
    """The still period's end for the components it configures then. Before it: the configured
    settings and noise (`settings`, `arw_rad_sqrt_s`, `compass_var_rad2`), zero x/y biases. `learner(x0,
    P0, Q)` builds the parameter learner (default: the STKF of the settings in force)."""

    def __init__(self, cfg: EstimatorConfig, model: DriftModel, learner: LearnerFactory | None, still: StillPeriod,
                 inputs: EstimatorInputs, gate: MagneticGate, heading: HeadingFilter, blocks: CompassBlocks,
                 learning: DriftLearning, prediction: DriftPrediction):
        self.model, self.still, self.inputs, self.gate, self.heading = model, still, inputs, gate, heading
        self.blocks, self.learning, self.prediction = blocks, learning, prediction
        self.learner_factory = learner or (lambda x0, P0, Q: self.settings.stkf(x0, P0, Q, self.model))
        self.settings = cfg                  # the settings in force (for the compass's rate from the end on)
        self.started = False
        self.still_use: str | None = None    # what the end did with the still period (still_period.initial_state)
        self.compass_period_s: float | None = None   # measured over the still period, s
        self.arw_rad_sqrt_s = cfg.arw_rad_sqrt_s   # the one angle random walk, rad/sqrt(s)
        self.compass_var_rad2 = (cfg.compass_sigma_rad or cfg.compass_sigma_default_rad) ** 2
        self.bias_xy = np.zeros(2)           # x/y gyro biases, rad/s

    def first_motion(self, t: np.ndarray, gyro: np.ndarray, acc: np.ndarray, integrator: GyroIntegrator) -> int | None:
        """Index of the first sample whose gyro heading left the start by `still_motion_rad`."""
        d_hat, bias_xy = self.still.running_mean(gyro)
        return self.still.first_motion(t, integrator.probe_heading(t, gyro, acc, d_hat, bias_xy))

    def finish(self, t_start: float, cfg: EstimatorConfig, t_origin: float, warm: dict | None,
               live_row: np.ndarray) -> None:
        """End of the still period at `t_start` (s) under the configured settings `cfg`: the settings
        for the compass's measured rate, biases, initial parameters (from `warm`: x and P or None,
        or None) and learner, compass noise, the gyro noise the stream carries."""
        self.compass_period_s = self.inputs.mag_period.period_s
        cfg = cfg.for_compass_period(self.compass_period_s)   # the settings in force from now on
        self.learning.settings = replace(self.learning.settings, window_s=cfg.window_s, edge_s=cfg.edge_s)
        self.gate.set_config(cfg.gate)
        self.settings = cfg
        self.prediction.coverage.memory_s = cfg.memory_s()
        still = self.still.finish(self.arw_rad_sqrt_s, cfg.r_floor_rad_s)
        self.take_noise(still)
        self.bias_xy = still.mean_rates_rad_s[:2].copy()
        t0 = still.temperature_c if still.temperature_c is not None else self.inputs.temp_fallback_c
        if cfg.compass_sigma_rad is None and still.compass_var_rad2 is not None and not still.cut_short:
            self.compass_var_rad2 = still.compass_var_rad2
        x0, P0, self.still_use = initial_state(self.model, still, t0, cfg.prior_sigma_values(self.model), warm,
                                               cfg.reject_sigma)
        learner = self.learner_factory(x0, P0, cfg.q_matrix(self.model))
        self.started = True
        self.learning.start(learner, t_start, t_origin, live_row)
        if still.cut_short or self.still_use == 'refused':
            # the unit moved: the gyro heading integrated with the running mean as its drift, and
            # the compass levelled by a tilt taken on the move, are no heading: unknown, as after
            # a time gap, until the gate passes the compass
            self.blocks.on_gap(math.pi ** 2)

    def take_noise(self, still: StillResult) -> None:
        """The angle random walk in force: the configured one (the sensor's noise density), or what
        the still period measured where that is significantly larger (still_period.py): the stream
        carries more noise than the sensor's density (point sampling, vibration), and R, the gate's
        allowances and the heading sigma must know it."""
        if still.arw_rad_sqrt_s is not None and still.arw_rad_sqrt_s != self.arw_rad_sqrt_s:
            self.arw_rad_sqrt_s = still.arw_rad_sqrt_s
            self.gate.arw_rad_sqrt_s = self.arw_rad_sqrt_s
            self.heading.arw_rad_sqrt_s = self.arw_rad_sqrt_s
