"""What a node publishes about the estimator, as plain dictionaries read from its components.

`estimator_diagnostics`: a snapshot of the estimate (parameters and their sigmas, the drift and
heading uncertainties, the gate and its references, the noise and settings in force) with every
counter; `estimator_counters`: event counts since construction (dropped inputs by stream and
reason, time gaps, heading rollbacks, gate refits, windows, learner steps). Reading them changes
nothing.
"""
from __future__ import annotations

import math

from .reasons import reason_names


def estimator_diagnostics(est) -> dict:
    """Snapshot of a `ThermalDriftEstimator` for a node's diagnostics: parameters, sigmas, gate, counters."""
    # the latest output row carries the estimator's reasons too (no compass, gap, stale temperature)
    latest = est.output.latest or est.blocks.latest
    gate, inputs, learning, prediction = est.gate, est.inputs, est.learning, est.prediction
    return {'started': est.startup.started, 'params': est.model.paper_coefficients(est.params),
            'param_sigmas': dict(zip(est.model.names, est.param_state.sigmas().tolist())),
            'drift_sigma_rad_s': est.drift_sigma.published(learning.sigma_d),
            'drift_change_weight': prediction.kappa, 'input_coverage': prediction.coverage.to_dict(),
            'window_r_scale': learning.r_scale,
            'drift_backtest_sigma_rad_s': math.sqrt(est.drift_sigma.backtest_var),
            'temperature_age_s': inputs.age_s(est.gyro.t_last),
            'gate_open': bool(latest.open[0]), 'gate_reasons': reason_names(latest.reasons[0]),
            'coasting_for_s': float(est.heading.tau_coast), 'heading_sigma_rad': est.heading.sigma_rad,
            'temperature_stuck': inputs.temp.stuck, 'temperature_stuck_for_s': inputs.temp.stuck_for_s(),
            'compass_sigma_rad': math.sqrt(est.startup.compass_var_rad2),
            'gate_reference': {'field_norm_t': gate.ref_norm, 'dip_rad': gate.ref_dip,
                               'accel_norm_m_s2': gate.reference.at('accel_norm', math.nan),
                               'slopes_per_c': gate.reference.slopes(),
                               'noise_sigma': gate.reference.noise_sigmas()},
            'arw_deg_sqrt_s': math.degrees(est.arw_rad_sqrt_s), 'compass_period_s': est.startup.compass_period_s,
            'window_s': est.drift_window_s,
            'coasting_s': est.blocks.coasting_s, **est.counters()}


def estimator_counters(est) -> dict[str, int]:
    """Event counts of a `ThermalDriftEstimator` since construction: dropped inputs by stream and
    reason, gaps, windows."""
    c = {**est.inputs.counters(), 'mag_dropped_late': est.mag_dropped_late, 'time_gaps': est.time_gaps,
         'heading_rollbacks': est.blocks.rollbacks,
         'heading_probation_rollbacks': est.blocks.probation_rollbacks,
         'gate_drift_lines': est.gate.n_drift_lines,
         **{f'gate_reference_refits_{k}': v for k, v in est.gate.reference.refits.items()},
         **est.learning.counters}
    learner = est.learner
    if learner is not None:
        c['filter_updates'] = learner.n_updates
        c['filter_rejected'] = learner.n_rejected
        c['filter_resets'] = learner.n_resets
    return c
