"""The methods `gyro-thermal-comp evaluate` runs side by side: the STKF, the paper's baselines and
the peers a user would pick instead, each with its documented default configuration."""
from __future__ import annotations

from ..thermal.baselines import (KfDriftBaseline, LsmBaseline, MlrCalibrated, MlrCalibration, MlrWholeRecord,
                                 UncompensatedBaseline)
from dataclasses import replace

from ..thermal.estimator import EstimatorConfig, ThermalDriftEstimator
from ..thermal.model_file import DriftModelFile
from .peers import default_peers


def all_methods(sample_rate_hz: float | None = None, config: EstimatorConfig | None = None,
                peers: bool = True, calibration: MlrCalibration | None = None,
                model_file: DriftModelFile | None = None) -> list:
    """STKF first; then KF, MLR calibrated beforehand (`mlr`: not applicable without `calibration`),
    modified LSM, uncompensated; then Fusion and Mahony; last the whole-record MLR fit
    (`mlr_whole_record`), an offline reference that is not causal. `model_file`: the STKF also runs
    that drift model (`stkf_model`, right after `stkf`: the model's effect side by side)."""
    cfg = config or EstimatorConfig()
    stkf = [ThermalDriftEstimator(cfg)]
    if model_file is not None:
        stkf.append(ThermalDriftEstimator(replace(cfg, name='stkf_model', drift_model_file=model_file)))
    methods = [*stkf, KfDriftBaseline(cfg), MlrCalibrated(calibration, cfg), LsmBaseline(cfg),
               UncompensatedBaseline(cfg)]
    if peers:
        methods += default_peers(sample_rate_hz)
    return methods + [MlrWholeRecord(cfg)]
