"""A sensor quantity that follows temperature: y = level + slope (T - ref_temp_c), learned online.

The magnetic gate judges the field's strength and dip, and the accelerometer's norm, against
references. An uncalibrated magnetometer's hard iron and sensitivity move with its temperature, so
in the sensor frame both |B| and the dip move with it (a static tag: 0.2 uT/degC and 0.2 deg/degC);
an accelerometer's scale factor does too (|f| at rest moved 0.3 m/s^2 over 11 degC). Each
reference is therefore a line in temperature:

- `TemperatureLine`: recursive least squares with exponential forgetting (memory `memory_s`) while
  the sensor is trusted; the slope's variance is capped at its prior, so it never stops learning.
- `ShutFit`: while a test is shut, the reference cannot learn from what it refuses. So the gate
  fits one straight line in temperature to the quantity over the shut. If that line explains the
  shut to the quantity's white noise, with a slope the sensor can have, AND passes through the
  reference at the temperature where the shut began (a temperature response is continuous: the
  reference was right there), the excursion was the sensor's own temperature response, not a field
  or an acceleration, and the reference takes the line (`explains`). A disturbance is a change the
  temperature does not explain: a step at a constant temperature puts the line off the reference
  at the shut by the whole step however long the shut lasts, and a line that would explain it by a
  0.01 degC quantization step has an impossible slope.
"""
from __future__ import annotations

import math

# a shut fit's residual rms may reach this many white-noise sigmas, or this fraction of the test's
# tolerance (a smooth structure well inside the tolerance, such as a short lag of the sensor's
# temperature, must not lock the gate), whichever is larger
RESIDUAL_SIGMAS = 1.5
RESIDUAL_TOL_FRACTION = 0.25
# a slope beyond this many prior sigmas is no temperature response of the sensor
SLOPE_PRIOR_SIGMAS = 3.0
MIN_POINTS = 20            # observations before a shut fit is judged


class TemperatureLine:
    """y = level + slope (T - ref_temp_c). `noise`: 1-sigma of one observation (its unit);
    `slope_prior`: 1-sigma of the slope about 0 (unit per degC), a ridge that forgetting never
    removes: a temperature that holds still leaves the slope at what the prior and the remembered
    data say, instead of letting the level and the slope wander together along the line's one
    unobserved direction."""

    def __init__(self, noise: float, slope_prior: float):
        self.noise = float(noise)
        self.slope_prior = float(slope_prior)
        self.ref_temp_c: float | None = None
        self.x: list[float] | None = None      # [level, slope]
        self._info: tuple | None = None        # information matrix of x, ((a, b), (b, c))
        self._eta: tuple | None = None         # information vector

    @property
    def level(self) -> float | None:
        return None if self.x is None else self.x[0]

    @property
    def slope(self) -> float:
        return 0.0 if self.x is None else self.x[1]

    def at(self, temperature_c: float) -> float:
        """Expected value at a temperature (degC); the level where it is unknown; NaN before any."""
        if self.x is None:
            return math.nan
        u = temperature_c - self.ref_temp_c if temperature_c == temperature_c else 0.0
        return self.x[0] + self.x[1] * u

    def _prior_info(self) -> float:
        return 1.0 / self.slope_prior ** 2 if self.slope_prior > 0 else 1e300

    def _take(self, x: list[float], info_diag: tuple[float, float]) -> None:
        self.x = [float(x[0]), float(x[1])]
        self._info = ((info_diag[0], 0.0), (0.0, info_diag[1]))
        self._eta = (info_diag[0] * self.x[0], info_diag[1] * self.x[1])

    def set_level(self, level: float, temperature_c: float) -> None:
        """A new level measured at `temperature_c` (a learning period's mean); the slope is kept."""
        if self.ref_temp_c is None:
            self.ref_temp_c = float(temperature_c) if temperature_c == temperature_c else 0.0
        u = temperature_c - self.ref_temp_c if temperature_c == temperature_c else 0.0
        (a, b), (_, c) = self._info or ((1.0, 0.0), (0.0, 0.0))
        slope_info = max(c - b * b / max(a, 1e-300), self._prior_info())   # what the data said of the slope
        self._take([float(level) - self.slope * u, self.slope], (1.0 / self.noise ** 2, slope_info))

    def set_line(self, level: float, slope: float, ref_temp_c: float, level_var: float, slope_var: float) -> None:
        """Take a fitted line (a shut fit's)."""
        self.ref_temp_c = float(ref_temp_c)
        self._take([level, slope], (1.0 / max(level_var, self.noise ** 2 * 1e-4),
                                    max(1.0 / max(slope_var, 1e-300), self._prior_info())))

    def step(self, y: float, temperature_c: float, lam: float) -> None:
        """One step of exponentially weighted least squares (forgetting factor `lam` =
        exp(-dt / memory)) with the slope's prior kept at full weight. (Python floats: the gate
        calls it per observation.)"""
        if self.x is None or not self.noise > 0:   # (a reference of exactly zero: synthetic input)
            return
        u = temperature_c - self.ref_temp_c if temperature_c == temperature_c else 0.0
        w = 1.0 / self.noise ** 2
        (a, b), (_, c) = self._info
        e0, e1 = self._eta
        a = lam * a + w
        b = lam * b + w * u
        c = lam * c + (1.0 - lam) * self._prior_info() + w * u * u
        e0 = lam * e0 + w * y
        e1 = lam * e1 + w * y * u
        self._info, self._eta = ((a, b), (b, c)), (e0, e1)
        det = a * c - b * b
        if det > 0:
            self.x = [(c * e0 - b * e1) / det, (a * e1 - b * e0) / det]


class ShutFit:
    """Least-squares line of y in temperature over the observations since `start` (O(1) each), and
    whether it explains them: sums about the first observation, for precision over long shuts."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        self._base: tuple[float, float] | None = None
        self._s = [0.0] * 6          # n, u, u^2, v, u v, v^2 (u = T, v = y, about the base)
        self._diff2 = 0.0            # sum of squared successive differences of y
        self._n_diff = 0
        self._last_y: float | None = None

    @property
    def n(self) -> int:
        return int(self._s[0])

    def add(self, y: float, temperature_c: float) -> None:
        if not (y == y and temperature_c == temperature_c):
            return
        if self._base is None:
            self._base = (temperature_c, y)
        u, v = temperature_c - self._base[0], y - self._base[1]
        s = self._s
        s[0] += 1.0
        s[1] += u
        s[2] += u * u
        s[3] += v
        s[4] += u * v
        s[5] += v * v
        if self._last_y is not None:
            self._diff2 += (y - self._last_y) ** 2
            self._n_diff += 1
        self._last_y = y

    def line(self) -> tuple[float, float, float, float, float] | None:
        """(level at the mean temperature, slope, mean temperature, residual rms, white-noise sigma
        from successive differences), None before `MIN_POINTS` observations."""
        n, su, suu, sv, suv, svv = self._s
        if n < MIN_POINTS or self._n_diff == 0:
            return None
        u_mean, v_mean = su / n, sv / n
        var_u = suu - su * u_mean
        cov = suv - su * v_mean
        slope = cov / var_u if var_u > 0.0 else 0.0
        rss = max(svv - sv * v_mean - slope * cov, 0.0)
        white = math.sqrt(self._diff2 / self._n_diff / 2.0)
        return v_mean + self._base[1], slope, u_mean + self._base[0], math.sqrt(rss / n), white

    def explains(self, tolerance: float, slope_prior: float, anchor: tuple[float, float]
                 ) -> tuple[float, float, float, float] | None:
        """The line (level at its mean temperature, slope, that temperature, its residual variance)
        if it explains the observations: residual at the white-noise level (or a small fraction of
        the test's `tolerance`), a slope the sensor can have, and within that fraction of the
        `anchor` (temperature degC, reference value) where the shut began; else None."""
        fit = self.line()
        if fit is None:
            return None
        level, slope, temp_mean, rms, white = fit
        allowed = max(RESIDUAL_SIGMAS * white, RESIDUAL_TOL_FRACTION * tolerance)
        if abs(slope) > SLOPE_PRIOR_SIGMAS * slope_prior or rms > allowed:
            return None
        t_anchor, y_anchor = anchor
        if not abs(level + slope * (t_anchor - temp_mean) - y_anchor) <= RESIDUAL_TOL_FRACTION * tolerance:
            return None
        return level, slope, temp_mean, rms * rms
