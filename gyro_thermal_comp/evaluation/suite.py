"""The methods `gyro-thermal-comp evaluate` runs side by side: the STKF, the paper's baselines and
the peers a user would pick instead, each with its documented default configuration."""
from __future__ import annotations

from ..thermal.baselines import KfDriftBaseline, LsmBaseline, MlrBaseline, UncompensatedBaseline
from ..thermal.estimator import EstimatorConfig, ThermalDriftEstimator
from .peers import default_peers


def all_methods(sample_rate_hz: float | None = None, config: EstimatorConfig | None = None,
                peers: bool = True) -> list:
    """STKF first; then KF, MLR, modified LSM, uncompensated; then Fusion and Mahony."""
    cfg = config or EstimatorConfig()
    methods = [ThermalDriftEstimator(cfg), KfDriftBaseline(cfg), MlrBaseline(cfg), LsmBaseline(cfg),
               UncompensatedBaseline(cfg)]
    if peers:
        methods += default_peers(sample_rate_hz)
    return methods
