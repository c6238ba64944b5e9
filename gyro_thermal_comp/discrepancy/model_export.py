"""What `discover` named, as the model file the vehicle's estimator runs (thermal/model_file.py).

The file keeps the discovered gyro terms the estimator can compute online (thermal/drift_model.py
BUILTIN_TERMS: temperature powers, dT/dt, the heating/cooling branch, scale factor) with the
input settings they need (die-temperature lag, branch time constant and rate scale). Each term's
starting value is its heading-axis (z) coefficient from the all-data fit; its prior 1-sigma is half
that value, kept between a tenth of the term's generic prior and the generic prior itself: the
same unit starts close to its calibration, yet the STKF can still move the parameter where the
unit has changed. A bias that wanders is the constant's random walk: a rate random walk K
(deg/s/sqrt(s)) is the `constant` term's q_sigma, and a bias instability of sigma over tau (a
first-order Gauss-Markov process) is driven by a white noise of sigma sqrt(2 / tau), the random
walk it looks like over less than tau; either raises the term's default, never lowers it. Terms the
estimator cannot compute online (a specific-force or cross-axis sensitivity, a compass deviation, a
stamp offset) are listed under `source.left_out` with the reason, not silently dropped.
"""
from __future__ import annotations

import datetime
import math

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
            terms.append(TermSetting(name, q_sigma=_wander_q(spec.settings()) if name == 'constant' else None))
            continue
        sigma = min(generic, max(0.5 * abs(value), 0.1 * generic))
        terms.append(TermSetting(name, prior=float(value), prior_sigma=float(sigma)))
    settings = spec.settings()
    if 'time_offset_s' in settings:
        left_out.append('time_offset_s: not a drift-model term')
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


def _wander_q(settings: dict) -> float | None:
    """The `constant` term's random walk per sqrt(s), rad/s, from a named wander of the heading
    axis (None: none named, the term's default stands)."""
    generic = BUILTIN_TERMS['constant'].q_sigma
    q = 0.0
    rrw = settings.get('rate_random_walk_dps_rts')
    if rrw and len(rrw) > HEADING_AXIS and rrw[HEADING_AXIS]:
        q = max(q, math.radians(float(rrw[HEADING_AXIS])))
    sigma, tau = settings.get('bias_instability_dps'), settings.get('bias_instability_tau_s')
    if sigma and tau and len(sigma) > HEADING_AXIS and sigma[HEADING_AXIS] and tau[HEADING_AXIS]:
        q = max(q, math.radians(float(sigma[HEADING_AXIS])) * math.sqrt(2.0 / float(tau[HEADING_AXIS])))
    return max(q, generic) if q > 0 else None
