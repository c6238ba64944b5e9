"""Thermal drift compensation of a MEMS gyro by a strong-tracking Kalman filter (docs/design.md section 2).

Pure numpy/scipy/filterpy, no ROS: the nodes wrap `ThermalDriftEstimator`.
"""
from .drift_model import CURVATURE_TERMS, DEFAULT_TERMS, PAPER_TERMS, SCALE_FACTOR_TERMS, DriftModel, Term
from .estimator import EstimatorConfig, ThermalDriftEstimator, ThermalOutput
from .heading_filter import HeadingFilter, HeadingFilterConfig
from .learner import FixedParameters, LearnerFactory, ParameterLearner
from .magnetic_gate import GateConfig, MagneticGate
from .reasons import REASON_BIT, REASONS, reason_names
from .stkf import DriftWindow, StrongTrackingKF
from .temperature_rate import TemperatureRateEstimator

__all__ = ['CURVATURE_TERMS', 'DEFAULT_TERMS', 'PAPER_TERMS', 'SCALE_FACTOR_TERMS', 'DriftModel', 'Term',
           'EstimatorConfig', 'ThermalDriftEstimator', 'ThermalOutput', 'HeadingFilter', 'HeadingFilterConfig',
           'FixedParameters', 'LearnerFactory', 'ParameterLearner', 'GateConfig', 'MagneticGate',
           'REASON_BIT', 'REASONS', 'reason_names', 'DriftWindow', 'StrongTrackingKF', 'TemperatureRateEstimator']
