"""Two truth families: tune on the first ('A', the named scenarios), report on the second ('B').

    cfg = make_family_config('B', 'outages', seed=3)               # b_static_ramp_outages, drawn truth
    cfg = make_family_config('B', 'static', seed=3, shapes=['hysteresis_tanh'], profile='steps')
    cases = family_configs('B', 'discover_effects', seeds=range(5), imu_rate_hz=5.0)

Family B (family_b.py) draws effect shapes, sizes and profiles from the seed and is never used to
tune a default (docs/simulator.md, "Second truth family"). Both families give ordinary SimConfigs:
`simulate(cfg)` streams them, `cfg.outages` lists the interference spans and `cfg.outage_labels`
the phase each one sits on; `cfg.to_dict()['truth_family']` records what a family-B bag contains.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

from .config import SimConfig, make_config
from .effects import EFFECTS
from .family_b import SHAPES, VARIANTS
from .family_b_profiles import PROFILE_KINDS

FAMILIES = ('A', 'B')
KINDS = ('static', 'outages', 'vehicle', 'null')
PURPOSES = ('static', 'outages', 'vehicle', 'discover_effects')
_SCENARIO = {('A', 'static'): 'static_ramp', ('A', 'outages'): 'static_ramp_outages', ('A', 'vehicle'): 'vehicle_loop',
             ('A', 'null'): 'null', ('B', 'static'): 'b_static', ('B', 'outages'): 'b_static_ramp_outages',
             ('B', 'vehicle'): 'b_vehicle_loop', ('B', 'null'): 'b_static'}
# the discovery library's name for each shape (() = outside the library); a deterministic shape may
# also be answered `unexplained_residual`, never a stochastic name (rate_random_walk, bias_instability)
RIGHT_NAMES = {**{s: ('thermal_hysteresis',) for s in SHAPES if s.startswith('hysteresis')},
               **{s: ('thermal_lag',) for s in SHAPES if s.startswith('lag')},
               'curvature': ('thermal_curvature',), 'periodic': (), 'bias_step': (), 'none': ('no_missing_effect',)}
# the first family's thermal effects for the same question (their sizes: the effects' defaults)
A_DISCOVER = {'curvature': 'thermal_curvature', 'hysteresis': 'thermal_hysteresis', 'lag': 'thermal_lag'}
_NULL_PARAMS = {'temp_lag_s': 0.0, 'temp_noise_c': 0.0}      # as the first family's `null` scenario
_OFF = {name: 0.0 for name in EFFECTS}


def _fail(message: str):
    raise ValueError(message)


def shape_params(shapes) -> dict:
    """`shapes` -> the scenario's shape_* params. None: drawn; 'none' or (): only the paper model;
    names from SHAPES or categories ('hysteresis', 'lag': variant drawn) switch on those alone."""
    if shapes is None:
        return {}
    if isinstance(shapes, str):
        shapes = () if shapes == 'none' else (shapes,)
    out = {f'shape_{cat}': 0.0 for cat in VARIANTS}
    for name in shapes:
        if len(VARIANTS.get(name, ())) > 1:                  # a category of several: its variant is drawn
            del out[f'shape_{name}']
            continue
        if name not in SHAPES:
            _fail(f'unknown shape {name!r}; valid: none, {", ".join(SHAPES)}, hysteresis, lag')
        cat = next(c for c in VARIANTS if name == c or name.startswith(c + '_'))
        variant = name[len(cat) + 1:] or VARIANTS[cat][0]
        out[f'shape_{cat}'] = float(VARIANTS[cat].index(variant) + 1)
    return out


def make_family_config(family: str, kind: str, seed: int, *, shapes=None, shape_scale: float | None = None,
                       profile: str | None = None, **overrides) -> SimConfig:
    """A complete truth drawn from `seed`: family 'A' or 'B', kind 'static', 'outages', 'vehicle' or
    'null' (B: the paper model alone on a family-B profile, no other effect, as A's `null`).

    Family B only: `shapes` (see shape_params), `shape_scale` (factor on every shape size), `profile`
    (static/null: one of PROFILE_KINDS instead of drawn). `overrides` go to make_config (duration_s,
    effects, params, rates, unit_seed). Raises ValueError with one line on bad input."""
    if family not in FAMILIES:
        _fail(f'unknown family {family!r}; valid: {", ".join(FAMILIES)}')
    if kind not in KINDS:
        _fail(f'unknown kind {kind!r}; valid: {", ".join(KINDS)}')
    scenario = _SCENARIO[family, kind]
    params = dict(overrides.pop('params', None) or {})
    effects = overrides.pop('effects', None)
    if family == 'A':
        if shapes is not None or shape_scale is not None or profile is not None:
            _fail('shapes, shape_scale and profile are family-B settings; family A takes effects and params')
        return make_config(scenario, seed=seed, effects=effects, params=params or None, **overrides)
    if profile is not None:
        if kind not in ('static', 'null') or profile not in PROFILE_KINDS:
            _fail(f'profile {profile!r}: static and null runs take one of {", ".join(PROFILE_KINDS)}')
        scenario = f'b_static_{profile}'
    if kind == 'null':
        if shapes not in (None, 'none', ()):
            _fail('a null run has no shapes; use kind static with shapes=...')
        shapes, effects = 'none', {**_OFF, **(effects or {})}
        params = {**_NULL_PARAMS, **params}
    params.update(shape_params(shapes))
    if shape_scale is not None:
        params['shape_scale'] = shape_scale
    return make_config(scenario, seed=seed, effects=effects, params=params or None, **overrides)


@dataclass(frozen=True)
class FamilyCase:
    """One bag a benchmark should run, with what it contains and (discover) which answers are right."""
    family: str
    purpose: str
    seed: int
    label: str
    config: SimConfig
    shape: str | None = None              # discover_effects: the one shape (or effect) hidden; 'none': null bag
    right_names: tuple = ()               # discover_effects: the library's name(s) for it
    acceptable: tuple = ()                # discover_effects: right_names, or unexplained_residual for a shape


def family_configs(family: str, purpose: str, seeds: Iterable[int], **overrides) -> list[FamilyCase]:
    """The bags a benchmark runs for `purpose` ('static', 'outages', 'vehicle', 'discover_effects').

    static: family B cycles the profiles (seed index i -> PROFILE_KINDS[i % 5]). discover_effects:
    per seed one bag per shape (B: SHAPES; A: its thermal effects at their default size) with nothing
    else (as A's `null` scenario), plus a null bag. `overrides` go to every make_config (rates, ...)."""
    if purpose not in PURPOSES:
        _fail(f'unknown purpose {purpose!r}; valid: {", ".join(PURPOSES)}')
    if family not in FAMILIES:
        _fail(f'unknown family {family!r}; valid: {", ".join(FAMILIES)}')
    out = []
    for i, seed in enumerate(seeds):
        if purpose in ('outages', 'vehicle'):
            cfg = make_family_config(family, purpose, seed, **overrides)
            out.append(FamilyCase(family, purpose, seed, f'{cfg.scenario} seed {seed}', cfg))
        elif purpose == 'static':
            prof = PROFILE_KINDS[i % len(PROFILE_KINDS)] if family == 'B' else None
            cfg = make_family_config(family, 'static', seed, profile=prof, **overrides)
            out.append(FamilyCase(family, purpose, seed, f'{cfg.scenario} seed {seed}', cfg))
        else:
            out += _discover_cases(family, seed, overrides)
    return out


def _discover_cases(family: str, seed: int, overrides: dict) -> list[FamilyCase]:
    rest = {k: v for k, v in overrides.items() if k not in ('effects', 'params')}
    effects, params = dict(overrides.get('effects') or {}), dict(overrides.get('params') or {})
    cases = []
    if family == 'B':
        for shape in SHAPES + ('none',):
            if shape == 'none':
                cfg = make_family_config('B', 'null', seed, **overrides)
            else:
                cfg = make_family_config('B', 'static', seed, shapes=[shape], effects={**_OFF, **effects},
                                         params={**_NULL_PARAMS, **params}, **rest)
            acceptable = RIGHT_NAMES[shape] + (() if shape == 'none' else ('unexplained_residual',))
            cases.append(FamilyCase('B', 'discover_effects', seed, f'B {shape} seed {seed}', cfg, shape,
                                    RIGHT_NAMES[shape], acceptable))
        return cases
    for shape, effect in (*A_DISCOVER.items(), ('none', None)):
        extra = {} if effect is None else {effect: EFFECTS[effect].default}
        cfg = make_config('null', seed=seed, effects={**effects, **extra}, params=params or None, **rest)
        right = ('no_missing_effect',) if effect is None else (effect,)
        acceptable = right + (() if effect is None else ('unexplained_residual',))
        cases.append(FamilyCase('A', 'discover_effects', seed, f'A {shape} seed {seed}', cfg, shape, right, acceptable))
    return cases
