"""What every test of the magnetic gate is: `GateTest`, and the `Observation` the gate hands each
test (gate_tests.py holds the tests and their registry)."""
from __future__ import annotations


class Observation:
    """One compass observation and what the tests share about it (reused: set by the gate)."""
    __slots__ = ('t', 'r', 'psi_g', 'norm', 'dip', 'temp', 'accel', 'var', 'dt', 'was_open', 'turning',
                 'turn_closes', 'arw2', 'drift', 'hyst')

    def __init__(self):
        for name in self.__slots__:
            setattr(self, name, 0.0)


class GateTest:
    """One test of the gate. `name` is its reason (one bit, reasons.py)."""
    name = ''
    observe_disabled = False      # judged even where it may not shut the gate (the turn's side effects)

    def __init__(self, gate):
        self.gate = gate          # the gate's settings (`gate.cfg`), references and angle random walk

    @property
    def cfg(self):
        return self.gate.cfg

    def enabled(self) -> bool:
        """May this test shut the gate (its settings' switch)?"""
        return True

    def begin(self, obs: Observation) -> None:
        """Once per batch of observations: constants of the batch."""

    def value(self, obs: Observation, active: bool) -> float | None:
        """The statistic as a fraction of the threshold; None: nothing to judge against yet."""
        raise NotImplementedError

    def revise(self, fired: bool, obs: Observation) -> float | None:
        """After the hysteresis: a new value, judged against the release level, or None."""
        return None

    def decided(self, fired: bool, obs: Observation) -> None:
        """The test's decision for this observation, for what follows it."""

    def on_shut(self, obs: Observation) -> None:
        """The gate shut at this observation."""

    def on_reopen(self, obs: Observation) -> None:
        """The gate reopened at this observation."""

    def set_config(self, cfg) -> None:
        """The settings changed at run time."""
