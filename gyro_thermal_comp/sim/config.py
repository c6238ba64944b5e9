"""SimConfig: everything one run depends on, validated, with the unit's drawn coefficients.

A config is complete: simulate(cfg) reads nothing else, and cfg.to_dict() is what a bag records as
/sim/config, so a run can be reproduced from its bag.
"""
from __future__ import annotations

import math
import operator
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from .effects import EFFECTS
from .interference import Episode, draw_episodes
from .scenarios import PARAM_SPECS, SCENARIO_DEFS
from .sensors import PRESETS, ImuPreset
from .unit import AUX_UNIT_STREAM, UnitCoefficients, draw_unit

EPISODE_STREAM = 2
MAX_DURATION_S = 30 * 24 * 3600.0
MAX_RATE_HZ = 10000.0


@dataclass(frozen=True)
class SimConfig:
    scenario: str
    seed: int
    duration_s: float
    imu_rate_hz: float
    mag_rate_hz: float
    temp_rate_hz: float
    truth_rate_hz: float
    effects: dict           # every effect name -> value (scenario defaults, overridden)
    params: dict            # every param of the scenario -> value
    preset: ImuPreset
    unit: UnitCoefficients
    episodes: tuple[Episode, ...]
    aux_preset: ImuPreset | None = None      # auxiliary IMU (carousel_flip); None: no imu_aux stream
    aux_unit: UnitCoefficients | None = None
    unit_seed: int | None = None             # the unit's coefficients were drawn from this seed (None: `seed`)
    truth_family: object = None              # second truth family's draw (family_b.FamilyBTruth); None: first

    @property
    def outages(self) -> list[tuple[float, float]]:
        """Spans (start_s, end_s) with magnetic interference."""
        return [(ep.start_s, ep.end_s) for ep in self.episodes]

    @property
    def family(self) -> str:
        """'A': the first truth family (tune on it); 'B': the second (report only)."""
        return 'A' if self.truth_family is None else 'B'

    @property
    def outage_labels(self) -> tuple:
        """Per episode, the profile phase it sits on ('heating_ramp', 'hold_to_cooling_turn',
        'cooling_tail', 'vehicle'), or None where the scenario labels none."""
        fam = self.truth_family
        labels = fam.outage_labels if fam is not None else SCENARIO_DEFS[self.scenario].episode_labels
        return tuple(labels[i] if i < len(labels) else None for i in range(len(self.episodes)))

    def to_dict(self) -> dict:
        out = {
            'scenario': self.scenario, 'description': SCENARIO_DEFS[self.scenario].description,
            'seed': self.seed, **({} if self.unit_seed is None else {'unit_seed': self.unit_seed}),
            'duration_s': self.duration_s,
            'rates_hz': {'imu': self.imu_rate_hz, 'mag': self.mag_rate_hz, 'temperature': self.temp_rate_hz,
                         'truth': self.truth_rate_hz},
            'effects': dict(self.effects), 'effect_units': {n: EFFECTS[n].unit for n in self.effects},
            'params': dict(self.params), 'sensor': self.preset.to_dict(), 'unit': self.unit.to_dict(),
            'episodes': [ep.to_dict() for ep in self.episodes],
            'outages': [list(span) for span in self.outages],
        }
        if self.aux_preset is not None:   # only scenarios with an aux IMU carry these keys
            out['aux_sensor'] = self.aux_preset.to_dict()
            out['aux_unit'] = self.aux_unit.to_dict()
        if self.truth_family is not None:   # only the second family's runs carry this key
            out['truth_family'] = {**self.truth_family.to_dict(), 'outage_labels': list(self.outage_labels)}
        return out


def _fail(message: str):
    raise ValueError(message)


def _number(what: str, value, lo: float, hi: float) -> float:
    if isinstance(value, bool):
        _fail(f'{what} must be a number, got {value!r}')
    try:
        x = float(value)
    except (TypeError, ValueError):
        _fail(f'{what} must be a number, got {value!r}')
    if not math.isfinite(x):
        _fail(f'{what} must be finite, got {value!r}')
    if not lo <= x <= hi:
        _fail(f'{what} = {x:g} is out of range [{lo:g}, {hi:g}]')
    return x


def _rate(what: str, value, default: float) -> float:
    if value is None:
        return float(default)
    x = _number(what, value, 0.0, MAX_RATE_HZ)
    if x <= 0:
        _fail(f'{what} must be > 0, got {x:g}')
    return x


def make_config(scenario: str, *, seed: int = 0, duration_s: float | None = None,
                effects: Mapping[str, float] | None = None, params: Mapping[str, float] | None = None,
                imu_rate_hz: float | None = None, mag_rate_hz: float | None = None,
                temp_rate_hz: float | None = None, truth_rate_hz: float | None = None,
                unit_seed: int | None = None) -> SimConfig:
    """Validate and complete a run's configuration; None takes the scenario's default.

    `unit_seed` draws the sensor unit's coefficients from another seed than the noise, motion and
    episodes: the same unit on another run (a calibration run, then the run it is applied to).

    Raises ValueError with one line naming the offending input (and the valid names where it helps).
    """
    if not isinstance(scenario, str) or scenario not in SCENARIO_DEFS:
        _fail(f'unknown scenario {scenario!r}; valid: {", ".join(SCENARIO_DEFS)}')
    sc = SCENARIO_DEFS[scenario]
    seed = _seed('seed', seed)
    unit_seed = None if unit_seed is None else _seed('unit_seed', unit_seed)

    if duration_s is None:
        duration = sc.duration_s
    else:
        duration = _number('duration_s', duration_s, -math.inf, MAX_DURATION_S)
        if duration <= 0:
            _fail(f'duration_s must be > 0, got {duration:g}')

    d_imu, d_mag, d_temp, d_truth = sc.rates
    imu = _rate('imu_rate_hz', imu_rate_hz, d_imu)
    mag = _rate('mag_rate_hz', mag_rate_hz, d_mag)
    temp = _rate('temp_rate_hz', temp_rate_hz, d_temp)
    truth = _rate('truth_rate_hz', truth_rate_hz, imu if imu_rate_hz is not None and truth_rate_hz is None
                  else d_truth)
    ratio = imu / truth
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        _fail(f'imu_rate_hz / truth_rate_hz must be a whole number (truth stamps are IMU stamps), '
              f'got {imu:g} / {truth:g}')

    eff = dict(sc.effects)
    if effects is not None:
        if not isinstance(effects, Mapping):
            _fail(f'effects must be a mapping NAME -> VALUE, got {type(effects).__name__}')
        for name, value in effects.items():
            if name not in EFFECTS:
                _fail(f'unknown effect {name!r}; valid: {", ".join(EFFECTS)}')
            spec = EFFECTS[name]
            eff[name] = _number(f'effect {name} ({spec.unit})', value, spec.minimum, spec.maximum)

    preset = PRESETS[sc.preset]
    par = {**sc.params, 'gyro_noise_dps_rthz': preset.gyro.noise_density_dps_rthz}
    if params is not None:
        if not isinstance(params, Mapping):
            _fail(f'params must be a mapping NAME -> VALUE, got {type(params).__name__}')
        valid = sorted({*par, *sc.optional_params})
        for name, value in params.items():
            if name not in par and name not in sc.optional_params:
                _fail(f'unknown param {name!r} for scenario {scenario}; valid: {", ".join(valid)}')
            lo, hi, meaning = PARAM_SPECS[name]
            par[name] = _number(f'param {name} ({meaning})', value, lo, hi)
    if 'encoder_counts' in par and par['encoder_counts'] != round(par['encoder_counts']):
        _fail(f'param encoder_counts must be a whole number, got {par["encoder_counts"]:g}')

    unit = draw_unit(seed if unit_seed is None else unit_seed, preset, eff)
    specs, family = sc.episodes, None
    if sc.draw_truth is not None:         # second truth family: its own profile, shapes, a, b, c, outages
        family = sc.draw_truth(seed=seed, unit_seed=unit_seed, params=par, effects=eff, preset=preset)
        unit = replace(unit, gyro_a_dps_per_c=np.array(family.paper['a']),
                       gyro_b_dps_per_c_per_s=np.array(family.paper['b']), gyro_c_dps=np.array(family.paper['c']))
        specs = family.episode_specs
    episodes = draw_episodes(np.random.default_rng([seed, EPISODE_STREAM]), specs, duration)
    aux_preset = aux_unit = None
    if sc.aux_preset is not None:
        aux_preset = PRESETS[sc.aux_preset]
        aux_unit = draw_unit(seed if unit_seed is None else unit_seed, aux_preset, eff, stream=AUX_UNIT_STREAM)
    return SimConfig(scenario, seed, duration, imu, mag, temp, truth, eff, par, preset, unit, episodes,
                     aux_preset, aux_unit, unit_seed, family)


def _seed(what: str, value) -> int:
    try:
        if isinstance(value, bool):
            raise TypeError
        value = operator.index(value)
    except TypeError:
        _fail(f'{what} must be an integer, got {value!r}')
    if not 0 <= value < 2 ** 63:
        _fail(f'{what} must be in [0, 2**63), got {value}')
    return value
