"""The second truth family (report only): drawn effect shapes and sizes, drawn profiles, labelled outages.

Used to report, never to tune defaults (docs/simulator.md, "Second truth family"). A family-B
scenario is an ordinary scenario (registered by scenarios.py, names `b_*`) whose `draw_truth` gives
make_config a `FamilyBTruth`: the case-temperature profile, the effect shapes with their sizes,
and the outages with their phase labels. cfg.to_dict()['truth_family'] records all of it.

Random streams (numpy [seed, id]; the first family uses 1-4, 10-13, 20-24): per unit (`unit_seed`,
else `seed`) 43 paper coefficients, 44 shapes; per run (`seed`) 40 profile, 41 outages, 42 step
times and the periodic phase. Every value is drawn whatever is switched on, so switching a shape
or resizing never changes another draw of the same seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from .family_b_drift import FamilyBDrift
from .family_b_profiles import (OUTAGE_KINDS, PROFILE_KINDS, VEHICLE_KINDS, Profile, draw_profile, log_uniform,
                                place_outages)
from .world import Scenario, World, earth_vectors, tilt_gains

PROFILE_STREAM, OUTAGE_STREAM, EVENT_STREAM, PAPER_STREAM, SHAPE_STREAM = 40, 41, 42, 43, 44

# category -> variants, in the order of the param codes 1, 2, ... (0 = off)
VARIANTS = {'hysteresis': ('sign', 'tanh', 'relaxation'), 'lag': ('first_order', 'second_order'),
            'curvature': ('cubic',), 'periodic': ('sinusoid',), 'bias_step': ('steps',)}
# names a benchmark asks for: 'category_variant' where a category has several variants
SHAPES = ('hysteresis_sign', 'hysteresis_tanh', 'hysteresis_relaxation', 'lag_first_order', 'lag_second_order',
          'curvature', 'periodic', 'bias_step')
# nominal z-axis sizes (the first family's defaults where it has the effect); drawn x U_log(0.5, 2)
NOMINAL = {'hysteresis': 4e-3,        # deg/s: ~1 % of the 0.35 deg/s thermal null shift between branches
           'curvature': 6e-5,         # deg/s/degC^2: a few 1e-3 deg/s non-linearity over 35 degC
           'periodic': 3e-3,          # deg/s: below the ADXRS623's 25 deg/h (7e-3 deg/s) bias stability
           'bias_step': 4e-3}         # deg/s: a bias jump of the bias-stability class
SIZE_SPREAD = (0.5, 2.0)
PRESENT_P = {'periodic': 0.5, 'bias_step': 0.5}   # drawn presence; the others are always on by default
CUBIC_REF_C = 20.0            # k3 = share * k2 / CUBIC_REF_C: at 20 degC from 25 the cubic is share x the square
STEP_MARGIN_S = 120.0         # bias steps keep this far from outages (a step inside one is unobservable)
THERMAL_A_EFFECTS = ('thermal_curvature', 'thermal_hysteresis', 'thermal_lag')

PARAM_SPECS = {
    'shape_hysteresis': (0.0, 3.0, 'family B hysteresis: 0 off, 1 sign, 2 tanh, 3 relaxation (absent: drawn)'),
    'shape_lag': (0.0, 2.0, 'family B die-temperature lag: 0 off, 1 first order, 2 second order (absent: drawn)'),
    'shape_curvature': (0.0, 1.0, 'family B curvature (square + random cubic share): 0 off, 1 on (absent: on)'),
    'shape_periodic': (0.0, 1.0, 'family B slow periodic disturbance: 0 off, 1 on (absent: drawn, p 0.5)'),
    'shape_bias_step': (0.0, 1.0, 'family B bias steps: 0 off, 1 on (absent: drawn, p 0.5)'),
    'shape_scale': (0.0, 100.0, 'family B: factor on every drawn shape size (absent: 1)'),
}
OPTIONAL = {name: None for name in PARAM_SPECS}


def _axis(rng) -> np.ndarray:
    """+-U(0.5, 1.5) on x, y; exactly +-1 on z (as the first family's unit draw)."""
    size, sign = rng.uniform(0.5, 1.5, 3), rng.choice([-1.0, 1.0], 3)
    size[2] = 1.0
    return sign * size


def _size(rng, category: str, scale: float) -> list:
    return (NOMINAL[category] * scale * log_uniform(rng, *SIZE_SPREAD) * _axis(rng)).tolist()


def _code(params: dict, name: str):
    v = params.get(name)
    if v is None:
        return None
    if v != round(v):
        raise ValueError(f'param {name} must be a whole number, got {v:g}')
    return int(v)


def _draw_shapes(rng, params: dict) -> dict:
    """Every shape's settings (all drawn, fixed order), then the ones switched on -> {category: record}."""
    scale = params.get('shape_scale')
    scale = 1.0 if scale is None else scale
    variant = {'hysteresis': int(rng.integers(3)), 'lag': int(rng.integers(2))}
    hyst = {'size_dps': _size(rng, 'hysteresis', scale), 'deadband_c_s': log_uniform(rng, 5e-4, 2e-3),
            'half_width_c': float(rng.uniform(1.0, 5.0)), 'sharpness': float(rng.uniform(1.0, 3.0))}
    fast = rng.uniform() < 0.5        # relaxation times away from the first family's 900 s
    hyst['tau_s'] = log_uniform(rng, 120.0, 600.0) if fast else log_uniform(rng, 1500.0, 5000.0)
    lag = {'tau_s': log_uniform(rng, 20.0, 300.0), 'tau1_s': log_uniform(rng, 15.0, 150.0),
           'tau2_s': log_uniform(rng, 15.0, 150.0)}
    k2 = _size(rng, 'curvature', scale)
    share = float(rng.uniform(-1.0, 1.0))
    curv = {'k2_dps_per_c2': k2, 'cubic_share': share,
            'k3_dps_per_c3': [share * k / CUBIC_REF_C for k in k2]}
    periodic = {'size_dps': _size(rng, 'periodic', scale), 'period_s': log_uniform(rng, 300.0, 2400.0)}
    steps = [_size(rng, 'bias_step', scale) for _ in range(2)]
    n_steps = 1 + int(rng.integers(2))
    present = {name: bool(rng.uniform() < p) for name, p in PRESENT_P.items()}

    codes = {cat: _code(params, f'shape_{cat}') for cat in VARIANTS}
    on = {}
    for cat in VARIANTS:
        c = codes[cat]
        if c is None:
            c = (variant[cat] + 1) if cat in variant else int(present.get(cat, True))
        if c:
            on[cat] = VARIANTS[cat][c - 1]
    out = {}
    if 'hysteresis' in on:
        v = on['hysteresis']
        keep = {'sign': ('deadband_c_s',), 'relaxation': ('deadband_c_s', 'tau_s'),
                'tanh': ('half_width_c', 'sharpness')}[v]
        out['hysteresis'] = {'variant': v, 'size_dps': hyst['size_dps'], **{k: hyst[k] for k in keep}}
    if 'lag' in on:
        v = on['lag']
        keep = ('tau_s',) if v == 'first_order' else ('tau1_s', 'tau2_s')
        out['lag'] = {'variant': v, **{k: lag[k] for k in keep}}
    if 'curvature' in on:
        out['curvature'] = {'variant': 'cubic', **curv}
    if 'periodic' in on:
        out['periodic'] = {'variant': 'sinusoid', **periodic}
    if 'bias_step' in on:
        out['bias_step'] = {'variant': 'steps', 'steps': [{'size_dps': s} for s in steps[:n_steps]]}
    return out


def _allowed_time(u: float, lo: float, hi: float, blocked: list) -> float:
    """Map u in [0, 1) onto [lo, hi] minus the blocked spans (no rejection loop: deterministic)."""
    free, cur = [], lo
    for a, b in sorted(blocked):
        if a > cur:
            free.append((cur, min(a, hi)))
        cur = max(cur, b)
    if cur < hi:
        free.append((cur, hi))
    free = [(a, b) for a, b in free if b > a]
    total = sum(b - a for a, b in free)
    x = u * total
    for a, b in free:
        if x <= b - a:
            return a + x
        x -= b - a
    return free[-1][1]


def _vehicle_outages(rng, duration_s: float, still_s: float) -> list[tuple]:
    """Three short episodes (15-30 s), one in each third of the drive after still_s + 200 s."""
    lo = still_s + 200.0
    third = (duration_s - lo - 60.0) / 3
    out = []
    for i, v in enumerate(rng.uniform(size=(3, 4))):
        dur = 15.0 + 15.0 * v[0]
        kind = 'rotate' if v[1] < 0.5 else 'strength'
        size = 15.0 + 10.0 * v[2] if kind == 'rotate' else 8.0 + 8.0 * v[2]
        out.append((kind, float(lo + i * third + v[3] * max(0.0, third - dur)), float(dur), float(size), 'vehicle'))
    return out


@dataclass(frozen=True)
class FamilyBTruth:
    """Everything drawn for one family-B run besides the first family's unit (which it amends)."""
    profile: Profile
    paper: dict              # a, b, c per axis, deg/s units; replaces the unit's
    shapes: dict             # category -> record of the shapes switched on
    outages: tuple           # (kind, start_s, duration_s, size, label), sorted by start

    @property
    def episode_specs(self) -> list[tuple]:
        return [o[:4] for o in self.outages]

    @property
    def outage_labels(self) -> tuple:
        return tuple(o[4] for o in self.outages)

    def drift(self, unit, rate_hz: float, t_case0_c: float) -> FamilyBDrift:
        return FamilyBDrift(a_dps_per_c=unit.gyro_a_dps_per_c, b_dps_per_c_per_s=unit.gyro_b_dps_per_c_per_s,
                            c_dps=unit.gyro_c_dps, shapes=self.shapes, rate_hz=rate_hz, t_case0_c=t_case0_c)

    def to_dict(self) -> dict:
        return {'family': 'B', 'profile': self.profile.to_dict(),
                'paper_model': {'a_dps_per_c': self.paper['a'], 'b_dps_per_c_per_s': self.paper['b'],
                                'c_dps': self.paper['c']},
                'shapes': self.shapes, 'shape_names': shape_names(self.shapes),
                'planned_outages': [{'kind': k, 'start_s': s, 'duration_s': d, 'size': z, 'label': lab}
                                    for k, s, d, z, lab in self.outages]}


def shape_names(shapes: dict) -> list[str]:
    """The SHAPES names of a truth's shapes record."""
    return [cat if len(VARIANTS[cat]) == 1 else f'{cat}_{rec["variant"]}' for cat, rec in shapes.items()]


def _paper(rng, preset) -> dict:
    """a, b, c around the datasheet class: |a|, |b| log-uniform over the preset's range widened to
    0.8x..1.25x, bias at 25 degC uniform in +-the preset's, random signs (deg/s units)."""
    g = preset.gyro
    sign = rng.choice([-1.0, 1.0], (2, 3))
    a = sign[0] * np.exp(rng.uniform(math.log(0.8 * g.slope_dps_per_c[0]), math.log(1.25 * g.slope_dps_per_c[1]), 3))
    b = sign[1] * np.exp(rng.uniform(math.log(0.8 * g.rate_coeff_dps_per_c_per_s[0]),
                                     math.log(1.25 * g.rate_coeff_dps_per_c_per_s[1]), 3))
    bias25 = rng.uniform(-g.bias_at_25c_dps, g.bias_at_25c_dps, 3)
    return {'a': a.tolist(), 'b': b.tolist(), 'c': (bias25 - a * 25.0).tolist()}


def draw_truth(*, kinds: tuple, nominal_s: float, outages: str, seed: int, unit_seed: int | None, params: dict,
               effects: dict, preset) -> FamilyBTruth:
    """The family-B draw of one run. kinds: the profile kinds drawn from; outages: 'phases' (labelled
    heating/turn/tail outages), 'vehicle' (three short ones) or 'none'. Sized for the scenario's
    nominal duration, so a shorter run is the start of the longer one."""
    for name in THERMAL_A_EFFECTS:
        if effects[name] != 0:
            raise ValueError(f'effect {name} is the first family\'s; family-B scenarios draw their own thermal '
                             f'shapes (params shape_*), so it must be 0')
    useed = seed if unit_seed is None else unit_seed
    shapes = _draw_shapes(np.random.default_rng([useed, SHAPE_STREAM]), params)
    paper = _paper(np.random.default_rng([useed, PAPER_STREAM]), preset)
    rng = np.random.default_rng([seed, PROFILE_STREAM])
    kind = kinds[int(rng.integers(len(kinds)))]
    t0 = params['still_s'] if 'still_s' in params else float(rng.uniform(120.0, 300.0))
    profile = draw_profile(kind, rng, t0, nominal_s)
    orng = np.random.default_rng([seed, OUTAGE_STREAM])
    spans = (place_outages(profile, orng, nominal_s) if outages == 'phases'
             else _vehicle_outages(orng, nominal_s, t0) if outages == 'vehicle' else [])
    erng = np.random.default_rng([seed, EVENT_STREAM])
    phase, u_steps = float(erng.uniform(0.0, 2 * np.pi)), erng.uniform(size=2)
    if 'periodic' in shapes:
        shapes['periodic']['phase_rad'] = phase
    if 'bias_step' in shapes:
        blocked = [(s - STEP_MARGIN_S, s + d + STEP_MARGIN_S) for _, s, d, _, _ in spans]
        steps = shapes['bias_step']['steps']
        for step, u in zip(steps, sorted(u_steps) if len(steps) == 2 else u_steps[:1]):   # monotone map: sorted
            step['t_s'] = float(_allowed_time(u, t0 + 300.0, nominal_s - 300.0, blocked))
    return FamilyBTruth(profile, paper, shapes, tuple(spans))


# --------------------------------------------------------------------------- scenarios
def _static_build(p, truth):
    from .motion import StaticPose
    from .mounts import FixedMount
    return World(StaticPose(np.deg2rad(p['roll_deg']), np.deg2rad(p['pitch_deg']), np.deg2rad(p['heading_deg'])),
                 FixedMount(), truth.profile, *earth_vectors(p))


def _vehicle_build(p, truth):
    from .motion import rectangle_laps
    from .mounts import FixedMount
    motion = rectangle_laps(heading_rad=np.deg2rad(p['heading_deg']), still_s=p['still_s'], speed=p['speed_mps'],
                            turn_speed=p['turn_speed_mps'], straight_s=p['straight_s'],
                            short_straight_s=p['short_straight_s'], turn_s=p['turn_s'], **tilt_gains(p))
    return World(motion, FixedMount(), truth.profile, *earth_vectors(p))


def scenario_defs(common: dict, rich: dict) -> tuple:
    """The family-B scenarios (scenarios.py passes the params and effects it shares)."""
    base = {k: v for k, v in common.items() if k != 'hysteresis_tau_s'}   # the first family's hysteresis
    off = {name: 0.0 for name in THERMAL_A_EFFECTS}
    static_p = {**base, 'roll_deg': 0.6, 'pitch_deg': -0.9}
    vehicle_p = {**base, 'still_s': 60.0, 'roll_gain_deg_per_mps2': 0.4, 'pitch_gain_deg_per_mps2': 0.3,
                 'speed_mps': 12.0, 'turn_speed_mps': 5.0, 'straight_s': 40.0, 'short_straight_s': 20.0, 'turn_s': 8.0}
    shapes = 'paper model a*T + b*dT/dt + c plus drawn effect shapes (lag, curvature, hysteresis; periodic ' \
             'and bias steps at p 0.5; params shape_*)'

    def static(name, kinds, text, outages='none'):
        return Scenario(name, f'family B (report only): motionless ADXRS623 unit, 2 h, {text}; {shapes}',
                            7200.0, 'adxrs623', _static_build, {**rich, **off}, static_p,
                            optional_params=OPTIONAL,
                            draw_truth=partial(draw_truth, kinds=kinds, nominal_s=7200.0, outages=outages))
    defs = [static('b_static', PROFILE_KINDS, 'profile drawn from ' + ', '.join(PROFILE_KINDS))]
    defs += [static(f'b_static_{k}', (k,), f'{k.replace("_", " ")} profile') for k in PROFILE_KINDS]
    defs.append(static('b_static_ramp_outages', OUTAGE_KINDS,
                       'profile drawn from ' + ', '.join(OUTAGE_KINDS) + ', magnetic interference of 300 s '
                       '(heating_ramp), 300 s (hold_to_cooling_turn) and 600 s (cooling_tail)', outages='phases'))
    defs.append(Scenario(
        'b_vehicle_loop', 'family B (report only): car with ADXRS623 unit, 60 s still, then rectangle laps as '
        f'vehicle_loop, 30 min, profile drawn from {", ".join(VEHICLE_KINDS)}, three short interference '
        f'episodes; {shapes}', 1800.0, 'adxrs623', _vehicle_build, {**rich, **off, 'compass_deviation': 3.0},
        vehicle_p, optional_params=OPTIONAL,
        draw_truth=partial(draw_truth, kinds=VEHICLE_KINDS, nominal_s=1800.0, outages='vehicle')))
    return tuple(defs)
