"""A gate test is one class and its registration: the gate builds it, hysteresis and hold-off apply
to it as to the built-in tests, and its reason reaches the output rows and the diagnostics by name
on its own bit, leaving every other reason's bit where it was."""
import numpy as np
import pytest

from gyro_thermal_comp.bag_io import BagReader
from gyro_thermal_comp.thermal.estimator import EstimatorConfig, ThermalDriftEstimator
from gyro_thermal_comp.thermal.gate_test_base import GateTest
from gyro_thermal_comp.thermal.gate_tests import GATE_TESTS, register_gate_test, unregister_gate_test
from gyro_thermal_comp.thermal.reasons import REASON_BIT, REASONS, reason_names, register_reason

from conftest import BAGS

CEILING_C = 23.2     # static_ramp_outages holds 23.0 degC for 3 min, then warms by ~0.25 degC/min
TOY_BIT = 20


class SensorTooWarm(GateTest):
    """Toy: the compass is not trusted above a temperature."""
    name = 'sensor_too_warm'

    def value(self, obs, active):
        return obs.temp / CEILING_C if obs.temp == obs.temp else None


@pytest.fixture
def toy_test():
    before = dict(REASON_BIT)
    register_gate_test(SensorTooWarm, TOY_BIT)
    yield SensorTooWarm
    unregister_gate_test(SensorTooWarm)
    assert REASON_BIT == before and SensorTooWarm not in GATE_TESTS


def test_a_registered_gate_test_shuts_the_gate_under_its_own_reason(toy_test):
    builtin_bits = {name: REASON_BIT[name] for name in REASONS}
    est = ThermalDriftEstimator(EstimatorConfig())
    assert [type(t) for t in est.gate.tests][-1] is SensorTooWarm
    seen, t_first = [], None
    with BagReader(BAGS / 'static_ramp_outages') as r:
        for chunk in r.chunks(chunk_s=10.0):
            out = est.process(chunk)
            toy = (out.reasons & (1 << TOY_BIT)) != 0
            if toy.any() and t_first is None:
                t_first = float(chunk.imu.t[np.argmax(toy)])
            seen.append(est.diagnostics()['gate_reasons'])
            if chunk.imu.t[-1] >= 330.0:
                break
    assert {name: REASON_BIT[name] for name in REASONS} == builtin_bits
    assert t_first is not None and 180.0 < t_first < 330.0   # where the temperature passed the ceiling
    assert 'sensor_too_warm' in seen[-1] and not est.diagnostics()['gate_open']
    assert all('sensor_too_warm' not in s for s in seen[:15])   # the first 150 s, at 23.0 degC
    assert reason_names(1 << TOY_BIT) == ['sensor_too_warm']


def test_a_taken_bit_or_name_is_refused():
    with pytest.raises(ValueError, match="bit 2 is already the reason 'heading_rate_mismatch'"):
        register_reason('new_reason', 2)
    with pytest.raises(ValueError, match="'field_norm' already has bit 0"):
        register_reason('field_norm', 21)
    with pytest.raises(ValueError, match='needs a reason bit'):
        register_gate_test(SensorTooWarm)
    assert SensorTooWarm not in GATE_TESTS and 'new_reason' not in REASON_BIT
