"""A sensor quantity that follows temperature: y = level + slope (T - ref_temp_c), learned online.

The magnetic gate judges the field's strength and dip, and the accelerometer's norm, against
references. An uncalibrated magnetometer's hard iron and sensitivity move with its temperature, so
in the sensor frame both |B| and the dip move with it (a static tag: 0.2 uT/degC and 0.2 deg/degC);
an accelerometer's scale factor does too (|f| at rest moved 0.3 m/s^2 over 11 degC). Each
reference is therefore a line in temperature:

- `TemperatureLine`: recursive least squares with exponential forgetting (memory `memory_s`) while
  the sensor is trusted; the slope's variance is capped at its prior, so it never stops learning.
- `ShutFit`: while a test is shut, the reference cannot learn from what it refuses. The reference
  was right where the gate last trusted the sensors (at temperature T_a it read y_a), and a
  temperature response is continuous, so the gate fits the line through (T_a, y_a) to the last
  `window_s` of the shut. If it
  explains them to the quantity's white noise, with a slope the sensor can have, the excursion is
  the sensor's own temperature response, not a field or an acceleration, and the reference takes
  the line (`explains`). A disturbance is a change the temperature does not explain: a step at a
  constant temperature sits off the anchor with no temperature difference to carry it, however long
  it lasts; and a disturbance early in the shut has left the window once it is over, so it cannot
  keep the reference from learning what the temperature did meanwhile.
"""
from __future__ import annotations

import math
from collections import deque

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
    """Least-squares slope of y in temperature through an anchor (T_a, y_a), over a trailing window
    of observations (O(1) each)."""

    def __init__(self, window_s: float):
        self.window_s = float(window_s)
        self.anchor: tuple[float, float] | None = None
        self._q: deque = deque()
        self._s = [0.0, 0.0, 0.0, 0.0]   # n, u^2, u v, v^2 (u = T - T_a, v = y - y_a)

    def clear(self) -> None:
        self.anchor = None
        self._q.clear()
        self._s = [0.0, 0.0, 0.0, 0.0]

    def start(self, temperature_c: float, y: float) -> None:
        self.clear()
        self.anchor = (float(temperature_c), float(y))

    def _add(self, u: float, v: float, w: float) -> None:
        s = self._s
        s[0] += w
        s[1] += w * u * u
        s[2] += w * u * v
        s[3] += w * v * v

    def add(self, t_s: float, y: float, temperature_c: float) -> None:
        if self.anchor is None or not (y == y and temperature_c == temperature_c):
            return
        u, v = temperature_c - self.anchor[0], y - self.anchor[1]
        self._q.append((t_s, u, v))
        self._add(u, v, 1.0)
        while self._q and self._q[0][0] <= t_s - self.window_s:
            _, u0, v0 = self._q.popleft()
            self._add(u0, v0, -1.0)

    @property
    def n(self) -> int:
        return int(round(self._s[0]))

    def explains(self, tolerance: float, slope_prior: float, white: float) -> float | None:
        """The slope (per degC) of the line through the anchor if it explains the window: residual
        rms within `RESIDUAL_SIGMAS` x the white noise (or a fraction of the test's tolerance), and a
        slope the sensor can have; else None."""
        n, suu, suv, svv = self._s
        if n < MIN_POINTS or not suu > 0.0:
            return None
        slope = suv / suu
        rms = math.sqrt(max(svv - slope * suv, 0.0) / n)
        if abs(slope) > SLOPE_PRIOR_SIGMAS * slope_prior:
            return None
        if rms > max(RESIDUAL_SIGMAS * white, RESIDUAL_TOL_FRACTION * tolerance):
            return None
        return slope
