"""Case-temperature profiles of the second truth family (report only, docs/simulator.md), drawn from a seed.

Five kinds, none of them the shapes of the first family's scenarios:
- fast_ramp / slow_ramp: hold, linear ramp with rounded corners, hold at the peak, exponential cooling;
- steps: set-point steps of a heated/cooled mass, each filtered by the case time constant;
- oscillating: ambient sinusoid (10-60 min period) starting from a hold with zero slope;
- cold_soak: soaked cold during the still period, then an exponential warm-up.

Every profile holds its start temperature until `t0` (the still period) and labels its phases
(times in s) so outages can be placed on them. Temperatures degC, times s, slopes degC/s.
"""
from __future__ import annotations

import math

import numpy as np

from .thermal import TemperatureProfile, approach_knots

PROFILE_KINDS = ('fast_ramp', 'slow_ramp', 'steps', 'oscillating', 'cold_soak')
OUTAGE_KINDS = ('fast_ramp', 'slow_ramp', 'steps')          # have a heating ramp, a turn and a cooling tail
VEHICLE_KINDS = ('steps', 'oscillating', 'cold_soak')       # change within a 30 min drive
OUTAGE_LABELS = ('heating_ramp', 'hold_to_cooling_turn', 'cooling_tail')
OUTAGE_DURATIONS_S = (300.0, 300.0, 600.0)
TURN_JITTER_S = 45.0          # the turn outage starts within this of where cooling starts


def log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


class Profile:
    """T(t) degC and dT/dt degC/s of one drawn profile, plus its labelled phases and drawn levels."""

    def __init__(self, kind: str, levels: dict, phases: dict):
        self.kind, self.levels, self.phases = kind, levels, phases

    def to_dict(self) -> dict:
        return {'kind': self.kind, **{k: float(v) for k, v in self.levels.items()},
                'phases_s': {k: float(v) for k, v in self.phases.items()}}


class _KnotProfile(Profile):
    """A C1 Hermite curve through knots in degC (thermal.TemperatureProfile on an identity scale)."""

    def __init__(self, kind, levels, phases, knots):
        super().__init__(kind, levels, phases)
        self._curve = TemperatureProfile(knots, 0.0, 1.0)

    def __call__(self, t_s):
        return self._curve(t_s)


class _StepProfile(Profile):
    """T = T0 + sum_i dT_i (1 - exp(-(t - t_i)/tau)) for t > t_i: set-point steps through the case lag."""

    def __init__(self, kind, levels, phases, steps, tau_s: float):
        super().__init__(kind, levels, phases)
        self._steps, self._tau, self._t0c = steps, tau_s, levels['start_c']

    def __call__(self, t_s):
        t = np.asarray(t_s, dtype=float)
        temp, slope = np.full(t.shape, self._t0c), np.zeros(t.shape)
        for t_i, d_i in self._steps:
            on = t > t_i
            e = np.exp(-np.maximum(t - t_i, 0.0) / self._tau)
            temp = temp + np.where(on, d_i * (1.0 - e), 0.0)
            slope = slope + np.where(on, d_i * e / self._tau, 0.0)
        return temp, slope


class _OscillatingProfile(Profile):
    """T = base + A (1 - cos(w (t - t0))) for t > t0: a sinusoidal ambient entered with zero slope."""

    def __init__(self, kind, levels, phases):
        super().__init__(kind, levels, phases)
        self._w = 2 * math.pi / levels['period_s']

    def __call__(self, t_s):
        t = np.asarray(t_s, dtype=float)
        u = np.maximum(t - self.phases['heat_start'], 0.0)
        amp = self.levels['amplitude_c']
        return (self.levels['start_c'] + amp * (1.0 - np.cos(self._w * u)),
                np.where(t > self.phases['heat_start'], amp * self._w * np.sin(self._w * u), 0.0))


def _ramp(kind, rng, t0, duration_s, span_c, ramp_s, hold_s, tau_s):
    start = rng.uniform(15.0, 30.0)
    span, ramp, hold, tau = (rng.uniform(*r) for r in (span_c, ramp_s, hold_s, tau_s))
    ambient = start + rng.uniform(-3.0, 3.0)
    corner = min(120.0, ramp / 4)
    rate = span / (ramp - corner)            # the straight part's slope; corners are parabolic
    peak, t_top, t_cool = start + span, t0 + ramp, t0 + ramp + hold
    knots = [(0.0, start, 0.0), (t0, start, 0.0), (t0 + corner, start + rate * corner / 2, rate),
             (t_top - corner, peak - rate * corner / 2, rate), (t_top, peak, 0.0)]
    knots += approach_knots(t_cool, peak, ambient, tau, t_end=4 * duration_s + 10000.0)
    return _KnotProfile(kind, {'start_c': start, 'peak_c': peak, 'ambient_c': ambient, 'ramp_rate_c_s': rate,
                               'cooling_tau_s': tau},
                        {'heat_start': t0, 'heat_end': t_top, 'cool_start': t_cool, 'cool_tau': tau}, knots)


def _steps(rng, t0, duration_s):
    start, tau = rng.uniform(15.0, 30.0), duration_s * rng.uniform(0.04, 0.12)
    up1, up2 = rng.uniform(8.0, 18.0), rng.uniform(4.0, 10.0)
    t2, t_cool = t0 + duration_s * rng.uniform(0.17, 0.25), t0 + duration_s * rng.uniform(0.45, 0.55)
    down = -(up1 + up2) + rng.uniform(-3.0, 3.0)
    steps = [(t0, up1), (t2, up2), (t_cool, down)]
    return _StepProfile('steps', {'start_c': start, 'step1_c': up1, 'step2_c': up2, 'step3_c': down,
                                  'case_tau_s': tau},
                        {'heat_start': t0, 'second_step': t2, 'heat_end': t_cool, 'cool_start': t_cool,
                         'cool_tau': tau}, steps, tau)


def _oscillating(rng, t0, duration_s):
    base, amp, period = rng.uniform(15.0, 35.0), rng.uniform(2.0, 8.0), log_uniform(rng, 600.0, 3600.0)
    return _OscillatingProfile('oscillating', {'start_c': base, 'amplitude_c': amp, 'period_s': period},
                               {'heat_start': t0, 'heat_end': t0 + period / 2, 'cool_start': t0 + period / 2})


def _cold_soak(rng, t0, duration_s):
    cold, warm = rng.uniform(-20.0, 5.0), rng.uniform(20.0, 40.0)
    soak_extra, tau = duration_s * rng.uniform(0.0, 0.05), duration_s * rng.uniform(0.1, 0.25)
    t_warm = t0 + soak_extra
    knots = [(0.0, cold, 0.0)] + approach_knots(t_warm, cold, warm, tau, t_end=4 * duration_s + 10000.0)
    return _KnotProfile('cold_soak', {'start_c': cold, 'warm_c': warm, 'warmup_tau_s': tau},
                        {'heat_start': t_warm}, knots)


def draw_profile(kind: str, rng, t0: float, duration_s: float) -> Profile:
    """One profile of `kind`, levels and times drawn from rng, changing from t0 s, sized for duration_s."""
    if kind == 'fast_ramp':
        return _ramp(kind, rng, t0, duration_s, (25.0, 40.0), (700.0, 1300.0), (300.0, 900.0), (600.0, 1500.0))
    if kind == 'slow_ramp':
        return _ramp(kind, rng, t0, duration_s, (15.0, 30.0), (1800.0, 2800.0), (300.0, 900.0), (1200.0, 2200.0))
    if kind == 'steps':
        return _steps(rng, t0, duration_s)
    if kind == 'oscillating':
        return _oscillating(rng, t0, duration_s)
    if kind == 'cold_soak':
        return _cold_soak(rng, t0, duration_s)
    raise ValueError(f'unknown profile kind {kind!r}; valid: {", ".join(PROFILE_KINDS)}')


def place_outages(profile: Profile, rng, duration_s: float) -> list[tuple]:
    """Outages at the labelled phases: (kind, start_s, duration_s, size, label), sorted by start.

    heating_ramp (300 s) inside the heating, once some of it has been seen (a ramp: after 30 % of it, at
    least 200 s; steps: on the second step's rise), hold_to_cooling_turn (300 s) starting
    within TURN_JITTER_S of where cooling starts, cooling_tail (600 s) once cooling has slowed (from
    1 to 2.5 cooling time constants after it started). Interference kind and size are drawn (rotate 15-30 deg,
    strength 8-20 uT)."""
    if profile.kind not in OUTAGE_KINDS:
        raise ValueError(f'profile {profile.kind} has no heating-turn-cooling sequence; outages need one of '
                         f'{", ".join(OUTAGE_KINDS)}')
    ph = profile.phases
    d_heat, d_turn, d_tail = OUTAGE_DURATIONS_S
    u = rng.uniform(size=4)
    if profile.kind == 'steps':           # the second step's rise (the first taught the heating), steepest early
        heat = ph['second_step'] + 30.0 + u[0] * max(0.0, 0.6 * ph['cool_tau'] - 30.0)
    else:                                 # after >= 200 s (30 %) of the ramp, ending >= 30 s before its top
        lo = ph['heat_start'] + max(200.0, 0.3 * (ph['heat_end'] - ph['heat_start']))
        hi = ph['heat_end'] - d_heat - 30.0
        heat = lo + u[0] * max(0.0, hi - lo)
    turn = ph['cool_start'] + TURN_JITTER_S * (2 * u[1] - 1)
    lo = max(turn + d_turn + 300.0, ph['cool_start'] + ph['cool_tau'])
    hi = min(duration_s - d_tail - 60.0, ph['cool_start'] + 2.5 * ph['cool_tau'])   # still cooling
    tail = min(lo + u[2] * max(0.0, hi - lo), hi)
    out = []
    for start, dur, label, v in zip((heat, turn, tail), OUTAGE_DURATIONS_S, OUTAGE_LABELS, rng.uniform(size=(3, 2))):
        kind = 'rotate' if v[0] < 0.5 else 'strength'
        size = 15.0 + 15.0 * v[1] if kind == 'rotate' else 8.0 + 12.0 * v[1]
        out.append((kind, float(start), dur, float(size), label))
    return out
