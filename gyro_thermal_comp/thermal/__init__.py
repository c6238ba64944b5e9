"""Thermal drift compensation of a MEMS gyro by a strong-tracking Kalman filter (design section 2).

Pure numpy/scipy/filterpy, no ROS: the nodes wrap `ThermalDriftEstimator`.
"""
from .drift_model import CURVATURE_TERMS, DEFAULT_TERMS, PAPER_TERMS, SCALE_FACTOR_TERMS, DriftModel, Term
from .estimator import REASONS, EstimatorConfig, ThermalDriftEstimator, ThermalOutput, reason_names
from .magnetic_gate import GateConfig, MagneticGate
from .heading_filter import HeadingFilter, HeadingFilterConfig
from .stkf import DriftWindow, StrongTrackingKF
from .temperature_rate import TemperatureRateEstimator

__all__ = ['CURVATURE_TERMS', 'DEFAULT_TERMS', 'PAPER_TERMS', 'SCALE_FACTOR_TERMS', 'DriftModel', 'Term',
           'REASONS', 'EstimatorConfig', 'ThermalDriftEstimator', 'ThermalOutput', 'reason_names',
           'GateConfig', 'MagneticGate', 'HeadingFilter', 'HeadingFilterConfig', 'DriftWindow',
           'StrongTrackingKF', 'TemperatureRateEstimator']
