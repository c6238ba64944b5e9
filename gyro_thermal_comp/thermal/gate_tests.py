"""The magnetic gate's tests, each one object, and the registry the gate builds them from.

A test reads its slice of the gate's settings, gives its statistic per observation as a fraction of
its threshold (`value`), and closes the gate under its own reason bit (reasons.py). The gate
(magnetic_gate.py) applies what every test shares: a test fires above 1 and releases below
`hysteresis`; the gate reopens only after `holdoff_s` with no test firing. Tests run in registry
order on each observation: the turn test first, because a turn re-learns the field's references
and restarts the heading-rate history.

A new test is one subclass of `GateTest` and `register_gate_test(cls, bit)`: the gate builds every
registered test, its reason appears in the records and in the diagnostics by name.
"""
from __future__ import annotations

from .gate_references import GateReferences
from .gate_test_base import GateTest, Observation
from .gate_mismatch import HeadingRateMismatch
from .reasons import REASON_BIT, register_reason, unregister_reason
from .trails import Trail, push_trail


class TurnRate(GateTest):
    """Turning faster than `turn_rate_rad_s`, the gyro heading's rate over `turn_window_s`: compass
    deviation depends on heading, so only straight segments are comparable. `turn_rate_enabled`
    False (turntables) keeps it from shutting the gate; a turn still re-learns the field references
    (their levels depend on heading on a vehicle) and restarts the heading-rate history."""
    name = 'turn_rate'
    observe_disabled = True

    def __init__(self, gate):
        super().__init__(gate)
        self.trail = Trail(gate.cfg.turn_window_s)

    def enabled(self) -> bool:
        return self.cfg.turn_rate_enabled

    def begin(self, obs: Observation) -> None:
        self.thr = float(self.cfg.turn_rate_rad_s)

    def value(self, obs: Observation, active: bool) -> float:
        g_old = push_trail(self.trail, obs.t, obs.psi_g)
        span = self.trail.span()
        return abs(obs.psi_g - g_old) / span / self.thr if span > 0 else 0.0

    def decided(self, fired: bool, obs: Observation) -> None:
        obs.turning = fired
        obs.turn_closes = fired and self.enabled()
        ref = self.gate.reference
        # reference levels: learned at the start (with the rest |f|) and again after every turn
        if not ref.started:
            ref.start_learning(obs.t, self.gate.reference_s, accel=True)
        elif fired:
            ref.start_learning(obs.t, self.cfg.reference_relearn_s)

    def set_config(self, cfg) -> None:
        self.trail.window_s = cfg.turn_window_s


class ReferenceTest(GateTest):
    """A quantity against its reference line in temperature (gate_references.py): fires where
    |y - reference(T)| exceeds the tolerance (or 4 sigma of its white noise, if larger). While it
    fires, a fit through the last trusted point may show the excursion is the sensor's own
    temperature response: the reference takes that line and the test is judged again."""
    reading = ''                  # the Observation field judged

    @property
    def ref(self) -> GateReferences:
        return self.gate.reference

    def usable(self, obs: Observation) -> bool:
        raise NotImplementedError

    def tolerance(self, obs: Observation) -> float:
        raise NotImplementedError

    def value(self, obs: Observation, active: bool) -> float | None:
        if not self.usable(obs):
            return None
        self._tol = self.ref.tolerance(self.name, self.tolerance(obs))
        return abs(getattr(obs, self.reading) - self.ref.at(self.name, obs.temp)) / self._tol

    def revise(self, fired: bool, obs: Observation) -> float | None:
        y = getattr(obs, self.reading)
        if fired:
            if self.ref.shut(self.name, True, obs.t, y, obs.temp, self._tol):
                return abs(y - self.ref.at(self.name, obs.temp)) / self._tol
        else:
            self.ref.shut(self.name, False, obs.t, y, obs.temp, self._tol)
        return None


class FieldNorm(ReferenceTest):
    """|B| off its reference by more than `field_norm_tol` (relative): most added fields. The
    reference follows the magnetometer's sensitivity in temperature (~0.3 %/degC)."""
    name, reading = 'field_norm', 'norm'

    def usable(self, obs: Observation) -> bool:
        ref = self.ref
        return ref.learn_until is None and ref.at('field_norm', obs.temp) > 0.0

    def tolerance(self, obs: Observation) -> float:
        return self.cfg.field_norm_tol * self.ref.at('field_norm', obs.temp)


class DipAngle(FieldNorm):
    """The inclination off its reference by more than `dip_tol_rad`."""
    name, reading = 'dip_angle', 'dip'

    def begin(self, obs: Observation) -> None:
        self.thr = float(self.cfg.dip_tol_rad)

    def tolerance(self, obs: Observation) -> float:
        return self.thr


class AccelNorm(ReferenceTest):
    """The accelerometer's norm off its value at rest by more than `accel_norm_tol_m_s2`: roll and
    pitch from gravity, hence the compass's tilt compensation, are wrong."""
    name, reading = 'accel_norm', 'accel'

    def usable(self, obs: Observation) -> bool:
        return self.ref.at('accel_norm', obs.temp) > 0.0

    def tolerance(self, obs: Observation) -> float:
        return self.cfg.accel_norm_tol_m_s2


GATE_TESTS: list[type[GateTest]] = [TurnRate, FieldNorm, DipAngle, AccelNorm, HeadingRateMismatch]


def register_gate_test(cls: type[GateTest], bit: int | None = None) -> None:
    """Add a test to every gate built from now on; `bit`: its reason's bit (a built-in name has one)."""
    if cls.name not in REASON_BIT:
        if bit is None:
            raise ValueError(f'gate test {cls.name!r} needs a reason bit')
        register_reason(cls.name, bit)
    if cls not in GATE_TESTS:
        GATE_TESTS.append(cls)


def unregister_gate_test(cls: type[GateTest]) -> None:
    """Remove a registered test and its reason (gates already built keep it)."""
    if cls in GATE_TESTS:
        GATE_TESTS.remove(cls)
    unregister_reason(cls.name)
