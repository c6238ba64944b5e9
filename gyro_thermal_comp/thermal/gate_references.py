"""`GateReferences`: what the field and the accelerometer read when they can be trusted, each a
line in temperature (temperature_line.py), and each observation's white noise; the magnetic gate's
field tests (gate_tests.py) judge against them."""
from __future__ import annotations

import math

import numpy as np

from .temperature_line import ShutFit, TemperatureLine


class GateReferences:
    """What the field and the accelerometer read when they can be trusted, each a line in
    temperature (temperature_line.py): |B| (T), the dip (rad) and the accelerometer's norm at rest
    |f| (m/s^2). Learned as plain means over a learning period (the still period at the start; the
    field's levels again after every turn, keeping their slopes), then by RLS (memory `memory_s`)
    while the gate is open. While a test is shut, a `ShutFit` per quantity may show the excursion
    was the sensor's temperature response (`refit`)."""

    NORM_NOISE = 2e-3           # block-mean |B| and |f| noise, relative to the level (RLS weights)
    DIP_NOISE_RAD = math.radians(0.2)
    SHUT_FIT_WINDOW_S = 60.0    # a shut fit judges the last minute of the shut
    MAX_FORGET_STEP_S = 10.0    # forgetting counts observed time: a compass silent for an hour
                                # does not erase what was learned before it
    NOISE_SIGMAS = 4.0          # a test fires at its tolerance or at this many sigmas of the
                                # observation's own white noise, whichever is larger

    def __init__(self, memory_s: float, norm_tc_prior: float, dip_tc_prior_rad: float):
        self.memory_s = memory_s
        self.norm_tc_prior = norm_tc_prior
        self.dip_tc_prior_rad = dip_tc_prior_rad
        self.lines: dict[str, TemperatureLine] = {}
        self.fits = {name: ShutFit(self.SHUT_FIT_WINDOW_S) for name in ('field_norm', 'dip_angle', 'accel_norm')}
        self.refits = dict.fromkeys(self.fits, 0)
        self.noise2 = dict.fromkeys(self.fits, 0.0)   # white-noise variance of each observation
        self._last_obs: tuple | None = None    # the previous observation (successive differences)
        self._n_noise = 0
        self.temp_open = math.nan                # the temperature at the latest open observation, degC
        self.learn_until: float | None = None  # (re)learning until then, s
        self.learn_accel = False               # this learning period also sets the rest |f|
        self.started = False
        self._sums = [0, 0.0, 0.0, 0.0, 0.0]   # count, sum |B|, sum dip, sum |f|, sum T of the learning period
        self._n_temp = 0
        self._decay_cache: dict = {}

    @property
    def norm(self) -> float | None:
        line = self.lines.get('field_norm')
        return None if line is None else line.level

    @property
    def dip(self) -> float | None:
        line = self.lines.get('dip_angle')
        return None if line is None else line.level

    def at(self, name: str, temperature_c: float) -> float:
        """The reference of `field_norm` (T), `dip_angle` (rad) or `accel_norm` (m/s^2) at a
        temperature (degC); NaN before one exists."""
        line = self.lines.get(name)
        return math.nan if line is None else line.at(temperature_c)

    def slopes(self) -> dict[str, float]:
        """The learned temperature slopes, per degC, in each reference's unit."""
        return {name: line.slope for name, line in self.lines.items()}

    def noise_sigmas(self) -> dict[str, float]:
        """Each observation's measured white noise, 1 sigma, in its reference's unit."""
        return {name: math.sqrt(v) for name, v in self.noise2.items()}

    def start_learning(self, t_s: float, duration_s: float, accel: bool = False) -> None:
        self.learn_until = t_s + duration_s
        self.learn_accel = accel
        self._sums = [0, 0.0, 0.0, 0.0, 0.0]
        self._n_temp = 0
        self.started = True
        for fit in self.fits.values():
            fit.clear()

    def _decay(self, dt_s: float) -> float:
        """exp(-dt / memory), cached: block observations come at a few fixed spacings."""
        key = (dt_s, self.memory_s)
        lam = self._decay_cache.get(key)
        if lam is None:
            if len(self._decay_cache) > 64:
                self._decay_cache.clear()
            lam = self._decay_cache[key] = float(np.exp(-max(dt_s, 0.0) / self.memory_s))
        return lam

    def _line(self, name: str, level: float) -> TemperatureLine:
        line = self.lines.get(name)
        if line is None:
            if name == 'dip_angle':
                line = TemperatureLine(self.DIP_NOISE_RAD, self.dip_tc_prior_rad)
            else:
                line = TemperatureLine(self.NORM_NOISE * abs(level), self.norm_tc_prior * abs(level))
            self.lines[name] = line
        return line

    def tolerance(self, name: str, tolerance: float) -> float:
        """A test's threshold: its tolerance, or `NOISE_SIGMAS` sigmas of the observation's white
        noise if larger (a 1 Hz tag's dip scatters 0.4 deg per sample: a 1 deg test fired on it)."""
        return max(tolerance, self.NOISE_SIGMAS * math.sqrt(self.noise2[name]))

    def _noise(self, obs: tuple, lam: float, learning: bool) -> None:
        """White-noise variance from successive differences (half their mean square), averaged
        over the learning period, then with forgetting `lam`."""
        last, self._last_obs = self._last_obs, obs
        if last is None:
            return
        self._n_noise += 1
        w = 1.0 / self._n_noise if learning else 1.0 - lam
        for name, y, y0 in zip(('field_norm', 'dip_angle', 'accel_norm'), obs, last):
            d2 = 0.5 * (y - y0) ** 2
            if d2 == d2:
                self.noise2[name] += w * (d2 - self.noise2[name])

    def observe(self, t_s, norm, dip, accel, temp, dt_obs, is_open) -> None:
        """Reference bookkeeping for one observation."""
        if self.learn_until is not None or is_open:
            self._noise((norm, dip, accel), self._decay(dt_obs), self.learn_until is not None)
        else:
            self._last_obs = None   # no differences across a shut
        if self.learn_until is not None:
            acc = self._sums
            acc[0] += 1
            acc[1] += norm
            acc[2] += dip
            acc[3] += accel
            if temp == temp:
                acc[4] += temp
                self._n_temp += 1
            if t_s >= self.learn_until:
                t_mean = acc[4] / self._n_temp if self._n_temp else math.nan
                names = ('field_norm', 'dip_angle') + (('accel_norm',) if self.learn_accel else ())
                for name, total in zip(names, acc[1:4]):
                    mean = total / acc[0]
                    if mean == mean:
                        self._line(name, mean).set_level(mean, t_mean)
                self.learn_until = None
            return
        if is_open:
            self.temp_open = temp
            lam = self._decay(min(dt_obs, self.MAX_FORGET_STEP_S))
            for name, y in (('field_norm', norm), ('dip_angle', dip), ('accel_norm', accel)):
                line = self.lines.get(name)
                if line is not None and y == y:
                    line.step(y, temp, lam)

    def shut(self, name: str, active: bool, t_s: float, y: float, temp: float, tolerance: float) -> bool:
        """While test `name` is active: one observation into its shut fit; True if the fit shows
        the excursion is the sensor's temperature response (the reference has taken the line)."""
        fit = self.fits[name]
        if not active:
            if fit.anchor is not None:
                fit.clear()
            return False
        line = self.lines.get(name)
        if line is None or not temp == temp:
            return False
        if fit.anchor is None:   # the reference was right where the gate last trusted the sensors
            t_a = self.temp_open if self.temp_open == self.temp_open else temp
            fit.start(t_a, line.at(t_a))
        fit.add(t_s, y, temp)
        slope = fit.explains(tolerance, line.slope_prior, math.sqrt(self.noise2[name]))
        if slope is None:
            return False
        line.set_line(fit.anchor[1], slope, fit.anchor[0], line.noise ** 2, line.slope_prior ** 2)
        self.refits[name] += 1
        fit.clear()
        return True
