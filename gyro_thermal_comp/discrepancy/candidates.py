"""The library of named candidate effects: physically meaningful additions to the model.

Each candidate turns the current `ModelSpec` into one or more candidate specs ("variants": the same
effect with different values of a non-linear setting such as a time constant, or model order).
Within each cross-validation fold the variant is chosen on the training blocks only, so a candidate
with many variants gets no free advantage on the held-out block; the information criterion counts
each estimated setting as a parameter.

Nothing here knows the simulator's values: time-constant grids span what thermal paths and
recorders produce (seconds to hours), rate scales are relative to the record's own heating rate.

Names are the simulator's effect names (sim/effects.py), so a finding maps onto one knob.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .model import Analysis, ModelSpec

GYRO, COMPASS, STOCHASTIC = 'gyro', 'compass', 'stochastic'


class Candidate:
    """A named missing effect. Subclasses set the class attributes and `variants`."""
    name = ''
    channel = GYRO
    n_settings = 0                       # non-linear settings estimated (counted by the IC)
    regime = 'time'                      # the variable its residual signature is best seen against
    adds: tuple = ()                     # gyro terms added (for the report and applicability)
    markov = False                       # stochastic channel: a Gauss-Markov state, not a random walk

    def applicable(self, an: Analysis, spec: ModelSpec) -> str | None:
        """None when testable on this record, else a one-line reason."""
        if self.name in spec.effects or (self.adds and all(t in spec.gyro_terms for t in self.adds)):
            return 'already in the model'
        return None

    def variants(self, an: Analysis, spec: ModelSpec) -> list[ModelSpec]:
        return [spec.with_terms(add=self.adds)]

    def refine(self, an: Analysis, spec: ModelSpec, best: ModelSpec) -> list[ModelSpec]:
        """Extra variants around the all-data best one (a finer grid); default none."""
        return []

    def named(self, spec: ModelSpec) -> ModelSpec:
        return replace(spec, effects=spec.effects + (self.name,))

    @classmethod
    def doc(cls) -> str:
        return ' '.join((cls.__doc__ or '').split())


def _alive_somewhere(an: Analysis, spec: ModelSpec, terms) -> bool:
    """Whether any of `terms` survives the excitation check on at least one axis."""
    trial = spec.with_terms(add=terms)
    fit = an.fit(trial, GYRO)
    return any(t in c.names for c in fit.comps for t in terms)


def _thermal_active(an: Analysis) -> str | None:
    span = np.ptp(an.temp[an.mask])
    return None if span > 0 and np.any(np.abs(an.temp_rate[an.mask]) > 0) else 'the temperature does not change'


def _log_grid(lo: float, hi: float, factor: float) -> list[float]:
    n = int(np.floor(np.log(hi / lo) / np.log(factor))) + 1
    return [float(lo * factor ** i) for i in range(n)]


class ThermalCurvature(Candidate):
    """Bias not linear in temperature: D += k2 (T - 25)^2 [+ k3 (T - 25)^3]. A MEMS null tempco is
    itself temperature dependent, so one linear a*T over 20-40 degC leaves a bowl-shaped residual
    against T, the same on heating and cooling. The order (2 or 3) is chosen by the IC."""
    name, regime = 'thermal_curvature', 'temperature'
    adds = ('temperature_squared', 'temperature_cubed')

    def applicable(self, an, spec):
        return super().applicable(an, spec) or _thermal_active(an) or (
            None if _alive_somewhere(an, spec, ('temperature_squared',)) else 'temperature span too small')

    def variants(self, an, spec):
        return [spec.with_terms(add=('temperature_squared',)),
                spec.with_terms(add=('temperature_squared', 'temperature_cubed'))]


class ThermalHysteresis(Candidate):
    """Heating and cooling branches differ: D += h m(t), with m = +1 after heating, -1 after
    cooling, relaxing towards 0 at a hold (m = first-order lag, time constant tau, of
    tanh((dT/dt)/r)). Package stress and moisture give such branch offsets; the residual against T
    splits into two parallel curves. tau (up to a quarter of the record) and r (relative to the
    record's heating rate) are estimated."""
    name, regime, n_settings = 'thermal_hysteresis', 'temperature', 2
    adds = ('thermal_branch',)

    def applicable(self, an, spec):
        return super().applicable(an, spec) or _thermal_active(an) or (
            None if np.sum(an.temp_rate[an.mask] > 0) and np.sum(an.temp_rate[an.mask] < 0)
            else 'the record only heats or only cools: no branches to compare')

    def _scales(self, an, spec):
        rate = an.thermal_inputs(spec)['temperature_rate'][an.mask]
        p95 = float(np.percentile(np.abs(rate), 95))
        return [p95 * f for f in (0.05, 0.15, 0.5)]

    def variants(self, an, spec):
        # the branch state must be able to settle within a quarter of the record: a slower "memory"
        # is a trend over the whole record, which any slow wander would also fit
        taus = [0.0] + _log_grid(60.0, max(120.0, an.data.duration_s / 4.0), 1.6)
        return [spec.with_terms(add=self.adds, branch=(tau, r)) for tau in taus for r in self._scales(an, spec)]

    def refine(self, an, spec, best):
        tau, r = best.branch
        return [spec.with_terms(add=self.adds, branch=(float(tau * ft), float(r * fr)))
                for ft in ((0.8, 0.9, 1.0, 1.12, 1.25) if tau > 0 else (1.0,)) for fr in (0.6, 0.8, 1.0, 1.25, 1.6)
                if (ft, fr) != (1.0, 1.0)]


class ThermalLag(Candidate):
    """The drift follows the die temperature, which lags the sensed temperature: every thermal
    term uses T_die = first-order lag (time constant tau, estimated) of T, and dT_die/dt =
    (T - T_die)/tau. A first-order lag is mostly absorbed by b*dT/dt; what is left shows where the
    heating rate changes (starts and ends of ramps)."""
    name, regime, n_settings = 'thermal_lag', 'temperature_rate', 1

    def applicable(self, an, spec):
        return super().applicable(an, spec) or _thermal_active(an)

    def variants(self, an, spec):
        hi = max(10.0, min(3600.0, an.data.duration_s / 4))
        return [replace(spec, lag_tau_s=tau) for tau in _log_grid(2.0 * an.data.bin_s, hi, 1.25)]

    def refine(self, an, spec, best):
        tau = best.lag_tau_s
        return [replace(spec, lag_tau_s=float(tau * f)) for f in (0.9, 0.95, 1.05, 1.1)]


class GSensitivity(Candidate):
    """Linear-acceleration sensitivity: D += G . f (f the measured specific force, m/s^2). Vibrating
    proof masses read acceleration as rate; on a static unit f is constant (hidden in c), so it needs
    accelerations (vehicle)."""
    name, regime = 'g_sensitivity', 'specific_force'
    adds = ('specific_force_x', 'specific_force_y', 'specific_force_z')

    def applicable(self, an, spec):
        return super().applicable(an, spec) or (
            None if _alive_somewhere(an, spec, self.adds) else 'the specific force does not change')


class ScaleFactor(Candidate):
    """Scale-factor error: gyro = (1 + s0) w, i.e. an error proportional to the true rate; shows in
    turns with the sign of the turn (needs a rate reference and rotation)."""
    name, regime = 'scale_factor', 'rate'
    adds = ('rate',)

    def applicable(self, an, spec):
        return super().applicable(an, spec) or (
            None if _alive_somewhere(an, spec, self.adds) else 'no rotation against a rate reference')


class ScaleFactorThermal(Candidate):
    """Temperature-dependent scale factor: gyro = (1 + k0 + k1 (T - 25)) w, the paper's k(T)
    (section 4.3): an error proportional to rate x temperature. Named only when the temperature
    dependence is significant beyond a constant scale factor."""
    name, regime = 'scale_factor_thermal', 'rate_temperature'
    adds = ('rate', 'rate_temperature')

    def applicable(self, an, spec):
        return super().applicable(an, spec) or _thermal_active(an) or (
            None if _alive_somewhere(an, spec, ('rate_temperature',)) else 'no rotation against a rate reference')


class CrossAxis(Candidate):
    """Cross-axis sensitivity / misalignment: each axis also reads a fraction of the rates about the
    two other axes (gyro_i += C_ij w_j). Seen on an axis that does not turn while another does."""
    name, regime = 'cross_axis', 'other_rate'
    adds = ('cross_rate_1', 'cross_rate_2')

    def applicable(self, an, spec):
        return super().applicable(an, spec) or (
            None if _alive_somewhere(an, spec, self.adds) else 'no rotation against a rate reference')


class TimeOffset(Candidate):
    """Gyro stamps offset from the reference (and temperature) clock: gyro(t) = w(t - dt) + D.
    Against a rate reference the residual is about -dt dw/dt: antisymmetric across each turn, zero
    in steady turns. dt (signed, s) is estimated; the reference is shifted exactly."""
    name, regime, n_settings = 'time_offset', 'rate_derivative', 1

    def applicable(self, an, spec):
        if super().applicable(an, spec):
            return 'already in the model'
        if not an.data.has_odom:
            return 'needs a moving unit with a rate reference'
        return None if _alive_somewhere(an, spec, ('rate',)) else 'no rotation against a rate reference'

    def variants(self, an, spec):
        # |dt| on a log grid (1.25x steps) from 0.5 ms to 1 s: the misfit of the nearest grid value is
        # a constant fraction of the effect at any size (a linear grid is too coarse for a few ms)
        return [replace(spec, time_offset_s=float(sign * dt)) for dt in _log_grid(5e-4, 1.0, 1.25)
                for sign in (1.0, -1.0)]

    def refine(self, an, spec, best):
        c = best.time_offset_s
        return [replace(spec, time_offset_s=float(c * f)) for f in (0.9, 0.95, 1.05, 1.1)]


class CompassDeviation(Candidate):
    """Heading-dependent magnetometer error from vehicle iron: hard iron gives a once-per-turn
    (sin psi, cos psi) deviation of the compass heading, soft iron a twice-per-turn one. Needs the
    magnetometer and a heading reference that turns."""
    name, channel, regime = 'compass_deviation', COMPASS, 'heading'

    def applicable(self, an, spec):
        if super().applicable(an, spec):
            return 'already in the model'
        if an.compass_mask is None:
            return 'needs a magnetometer and a heading reference (odom)'
        fit = an.fit(self.variants(an, spec)[0], COMPASS)
        return None if len(fit.comps[0].names) > 1 else 'the heading does not change'

    def variants(self, an, spec):
        return [replace(spec, compass_terms=spec.compass_terms + ('compass_sin1', 'compass_cos1',
                                                                  'compass_sin2', 'compass_cos2'))]


class RateRandomWalk(Candidate):
    """Rate random walk: a bias that wanders as a random walk (Allan deviation rising as
    sqrt(tau) at long averaging times). Not a regressor: it is modelled as a random-walk state
    whose level in a held-out block is interpolated from the neighbouring blocks (Kalman smoother);
    its strength K (rad/s/sqrt(s)) is estimated by (restricted) maximum likelihood (wander.py)."""
    name, channel, regime, n_settings = 'rate_random_walk', STOCHASTIC, 'time', 1


class BiasInstability(Candidate):
    """Bias instability: a bias that wanders but reverts to its mean over a correlation time tau (a
    first-order Gauss-Markov state, standard deviation sigma; the Allan deviation bump between the
    white-noise and random-walk slopes). Modelled like the random walk, with tau also estimated by
    maximum likelihood; the random walk is its tau -> infinity limit, so it is named instead only
    when the mean reversion is significant (choice._wander_choice)."""
    name, channel, regime, n_settings = 'bias_instability', STOCHASTIC, 'time', 2
    markov = True


LIBRARY: tuple[Candidate, ...] = (ThermalCurvature(), ThermalHysteresis(), ThermalLag(), GSensitivity(),
                                  ScaleFactor(), ScaleFactorThermal(), CrossAxis(), TimeOffset(),
                                  CompassDeviation(), RateRandomWalk(), BiasInstability())
BY_NAME = {c.name: c for c in LIBRARY}
