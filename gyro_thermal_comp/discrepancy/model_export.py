"""What `discover` named, as the model file the vehicle's estimator runs (thermal/model_file.py).

The file keeps the discovered gyro terms the estimator can compute online (thermal/drift_model.py
BUILTIN_TERMS: temperature powers, dT/dt, the heating/cooling branch, scale factor) with the
input settings they need (die-temperature lag, branch time constant and rate scale). Each term's
starting value is its heading-axis (z) coefficient from the all-data fit; its prior 1-sigma is half
that value, kept between a tenth of the term's generic prior and the generic prior itself: the
same unit starts close to its calibration, yet the STKF can still move the parameter where the
unit has changed. Terms the estimator cannot compute online (a specific-force or cross-axis
sensitivity, a compass deviation, a stamp offset) and stochastic settings are listed under
`source.left_out` with the reason, not silently dropped.
"""
from __future__ import annotations

import datetime

from ..thermal.drift_model import BUILTIN_TERMS
from ..thermal.model_file import DriftModelFile, TermSetting
from .model import T_REF_C

HEADING_AXIS = 2   # the z gyro: its coefficients are the heading drift's


def model_file_from_discovery(result, bag: str = '') -> DriftModelFile:
    """A `DriftModelFile` from a `DiscoveryResult`."""
    spec = result.spec_after
    coefs = result.coefficients.get('gyro') or [{}] * 3
    z = coefs[HEADING_AXIS] if len(coefs) > HEADING_AXIS else {}
    terms, left_out = [], []
    for name in spec.gyro_terms:
        if name not in BUILTIN_TERMS:
            left_out.append(f'{name}: needs an input the estimator does not compute online')
            continue
        generic = BUILTIN_TERMS[name].prior_sigma
        value = z.get(name)
        if value is None or name == 'constant':   # the still period re-measures the constant
            terms.append(TermSetting(name))
            continue
        sigma = min(generic, max(0.5 * abs(value), 0.1 * generic))
        terms.append(TermSetting(name, prior=float(value), prior_sigma=float(sigma)))
    settings = spec.settings()
    for key in ('time_offset_s', *(k for k in settings if k.startswith(('rate_random_walk', 'bias_instability')))):
        if key in settings:
            left_out.append(f'{key}: not a drift-model term')
    branch = None
    if 'hysteresis_tau_s' in settings:
        branch = (float(settings['hysteresis_tau_s']), float(settings['hysteresis_rate_scale_c_s']))
    source = {'written_by': 'gyro-thermal-comp discover --write-model', 'bag': str(bag),
              'date': datetime.date.today().isoformat(), 'verdict': result.verdict,
              'effects': list(result.effects)}
    if left_out:
        source['left_out'] = left_out
    return DriftModelFile(terms=tuple(terms), temperature_ref_c=T_REF_C,
                          lag_tau_s=float(settings.get('thermal_lag_tau_s', 0.0)), branch=branch, source=source)
