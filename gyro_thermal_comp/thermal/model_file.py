"""`DriftModelFile`: the drift model a vehicle's estimator runs, as a YAML file.

`gyro-thermal-comp discover BAG --write-model FILE` writes one from what it named; `stkf_node`
loads it (parameter `drift_model_file`), `replay`/`evaluate` with `--model FILE`. It holds:

    format: gyro_thermal_comp/drift_model/1
    temperature_ref_c: 25.0                   # temperature terms use T - this, degC
    terms:                                    # the STKF state (drift_model.py names; state files match by name)
      - {name: constant}
      - {name: temperature, prior: 1.1e-4, prior_sigma: 5.5e-5, q_sigma: 2.0e-8}
      - ...
    inputs:                                   # how derived inputs are computed (model_inputs.py)
      thermal_lag_tau_s: 95.0                 # die temperature lag, s (0: none)
      hysteresis_tau_s: 610.0                 # branch memory, s   } both or neither;
      hysteresis_rate_scale_c_s: 0.003        # branch rate scale  } needed by thermal_branch
    coverage:                                 # what the calibration record spanned (optional)
      temperature_c: [23.1, 57.9]
      temperature_rate_c_s: [-0.012, 0.021]
    source: {...}                             # provenance, free form (bag, verdict, date)

`prior` is the starting value of a parameter (SI; the still period re-measures `constant`), and
`prior_sigma` its 1-sigma; `q_sigma` its random walk per sqrt(s). Each defaults to the term's own
(drift_model.py). The STKF learns every coefficient online from there, as it does the paper's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .drift_model import BUILTIN_TERMS, DriftModel
from .model_inputs import ModelInputs

FORMAT = 'gyro_thermal_comp/drift_model/1'
_INPUT_KEYS = ('thermal_lag_tau_s', 'hysteresis_tau_s', 'hysteresis_rate_scale_c_s')


@dataclass(frozen=True)
class TermSetting:
    name: str
    prior: float | None = None          # starting value, SI (None: 0, or measured for `constant`)
    prior_sigma: float | None = None    # 1-sigma, SI (None: the term's default)
    q_sigma: float | None = None        # random walk per sqrt(s), SI (None: the term's default)


@dataclass(frozen=True)
class DriftModelFile:
    terms: tuple[TermSetting, ...]
    temperature_ref_c: float = 25.0
    lag_tau_s: float = 0.0
    branch: tuple[float, float] | None = None    # (hysteresis_tau_s s, hysteresis_rate_scale_c_s degC/s)
    coverage: dict | None = None                 # {'temperature_c': (lo, hi), 'temperature_rate_c_s': (lo, hi)}
    source: dict = field(default_factory=dict)

    def __post_init__(self):
        names = [t.name for t in self.terms]
        if not names:
            raise ValueError('a drift model file needs at least one term')
        unknown = [n for n in names if n not in BUILTIN_TERMS]
        if unknown:
            raise ValueError(f"term(s) {', '.join(unknown)} cannot run in the estimator "
                             f"(online terms: {', '.join(BUILTIN_TERMS)})")
        if len(set(names)) != len(names):
            raise ValueError(f'terms given twice: {sorted({n for n in names if names.count(n) > 1})}')
        if 'thermal_branch' in names and self.branch is None:
            raise ValueError('term thermal_branch needs inputs hysteresis_tau_s and hysteresis_rate_scale_c_s')
        for t in self.terms:
            for key in ('prior', 'prior_sigma', 'q_sigma'):
                v = getattr(t, key)
                if v is not None and not math.isfinite(v):
                    raise ValueError(f'term {t.name}: {key} must be finite, got {v}')
            if t.prior_sigma is not None and t.prior_sigma <= 0:
                raise ValueError(f'term {t.name}: prior_sigma must be > 0, got {t.prior_sigma}')
            if t.q_sigma is not None and t.q_sigma < 0:
                raise ValueError(f'term {t.name}: q_sigma must be >= 0, got {t.q_sigma}')
        self.model_inputs()   # validates the input settings

    # ------------------------------------------------------------------ what the estimator uses
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    def model(self) -> DriftModel:
        return DriftModel(self.names, self.temperature_ref_c)

    def model_inputs(self) -> ModelInputs:
        return ModelInputs(self.lag_tau_s, *(self.branch or (None, None)))

    def prior_sigmas(self) -> np.ndarray:
        return np.array([t.prior_sigma if t.prior_sigma is not None else BUILTIN_TERMS[t.name].prior_sigma
                         for t in self.terms])

    def q_sigmas(self) -> np.ndarray:
        return np.array([t.q_sigma if t.q_sigma is not None else BUILTIN_TERMS[t.name].q_sigma for t in self.terms])

    def priors(self) -> dict[str, float]:
        """Starting values given in the file, by term name (SI)."""
        return {t.name: float(t.prior) for t in self.terms if t.prior is not None}

    # ------------------------------------------------------------------ file
    def to_dict(self) -> dict:
        terms = [{'name': t.name, **{k: float(getattr(t, k)) for k in ('prior', 'prior_sigma', 'q_sigma')
                                     if getattr(t, k) is not None}} for t in self.terms]
        inputs = {'thermal_lag_tau_s': float(self.lag_tau_s)}
        if self.branch is not None:
            inputs['hysteresis_tau_s'], inputs['hysteresis_rate_scale_c_s'] = (float(v) for v in self.branch)
        out = {'format': FORMAT, 'temperature_ref_c': float(self.temperature_ref_c), 'terms': terms, 'inputs': inputs}
        if self.coverage:
            out['coverage'] = {k: [float(v) for v in lohi] for k, lohi in self.coverage.items()}
        if self.source:
            out['source'] = self.source
        return out

    @classmethod
    def from_dict(cls, d) -> 'DriftModelFile':
        if not isinstance(d, dict):
            raise ValueError('a drift model file is a YAML mapping')
        if d.get('format') != FORMAT:
            raise ValueError(f"format must be {FORMAT!r}, got {d.get('format')!r}")
        terms = d.get('terms')
        if not isinstance(terms, list) or not all(isinstance(t, dict) and isinstance(t.get('name'), str) for t in terms):
            raise ValueError('terms must be a list of mappings with a name')
        extra = [k for t in terms for k in t if k not in ('name', 'prior', 'prior_sigma', 'q_sigma')]
        if extra:
            raise ValueError(f'unknown term key(s) {sorted(set(extra))} (known: name, prior, prior_sigma, q_sigma)')
        inputs = d.get('inputs') or {}
        unknown = [k for k in inputs if k not in _INPUT_KEYS]
        if unknown:
            raise ValueError(f"unknown input setting(s) {unknown} (known: {', '.join(_INPUT_KEYS)})")
        branch = None
        if 'hysteresis_tau_s' in inputs or 'hysteresis_rate_scale_c_s' in inputs:
            branch = (_num(inputs, 'hysteresis_tau_s'), _num(inputs, 'hysteresis_rate_scale_c_s'))
        coverage = d.get('coverage')
        if coverage is not None:
            coverage = {k: _range(coverage, k) for k in ('temperature_c', 'temperature_rate_c_s')}
        return cls(terms=tuple(TermSetting(t['name'], *(None if t.get(k) is None else _num(t, k)
                                                           for k in ('prior', 'prior_sigma', 'q_sigma')))
                               for t in terms),
                   temperature_ref_c=_num(d, 'temperature_ref_c', 25.0), lag_tau_s=_num(inputs, 'thermal_lag_tau_s', 0.0),
                   branch=branch, coverage=coverage, source=dict(d.get('source') or {}))

    def save(self, path) -> Path:
        path = Path(path)
        text = '# gyro_thermal_comp drift model: stkf_node drift_model_file, replay/evaluate --model\n' + \
            yaml.safe_dump(self.to_dict(), sort_keys=False)
        path.write_text(text)
        return path

    @classmethod
    def load(cls, path) -> 'DriftModelFile':
        """ValueError with one line naming the file and what is wrong with it."""
        path = Path(path)
        try:
            return cls.from_dict(yaml.safe_load(path.read_text()))
        except OSError as e:
            raise ValueError(f'drift model file {path}: {e.strerror or e}') from None
        except yaml.YAMLError as e:
            raise ValueError(f'drift model file {path}: not YAML ({str(e).splitlines()[0]})') from None
        except (ValueError, TypeError) as e:
            raise ValueError(f'drift model file {path}: {e}') from None


def _num(d: dict, key: str, default=None) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f'{key} must be a finite number, got {v!r}')
    return float(v)


def _range(d: dict, key: str) -> tuple[float, float]:
    v = d.get(key)
    if not (isinstance(v, (list, tuple)) and len(v) == 2):
        raise ValueError(f'coverage.{key} must be [low, high]')
    lo, hi = (_num({'v': x}, 'v') for x in v)
    if lo > hi:
        raise ValueError(f'coverage.{key}: low {lo} > high {hi}')
    return lo, hi
