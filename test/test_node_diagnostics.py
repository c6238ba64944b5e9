"""/diagnostics in diagnostic_updater's sense: OK while the node works as designed (a turn coasted
through included), WARN when degraded, ERROR when broken; the key values a robot team reads, with
their units; a declared "no temperature sensor" is OK."""
import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from conftest import BAGS, Capture
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.samples import SensorChunk


def _drive(node, seconds: float, streams=('imu', 'mag', 'temperature')):
    """Feed the bundled drive; diagnostics once per second of it, as replay publishes them."""
    seen = []
    for chunk in read_chunks(BAGS / 'vehicle_loop', 1.0, streams=list(streams)):
        if chunk.imu.t[0] >= seconds:
            break
        node.process_chunk(SensorChunk(**{k: v for k, v in chunk.streams().items() if k in streams}))
        seen.append(node.diagnostic_values())
    return seen


def test_a_healthy_drive_is_ok_and_a_turn_is_coasted_through_ok(ros):
    """The first 10 min of the bundled drive: still period, laps with turns, a magnetic disturbance
    of 20 s. It was WARN for 49 % of the reports (turn rate, hold-off, still period)."""
    node = make_stkf_node({'declination_rad': math.radians(7.0)})
    node.pubs = {name: Capture() for name in node.pubs}
    seen = _drive(node, 600.0)
    node.destroy_node()
    levels = np.array([int.from_bytes(level, 'little') if isinstance(level, bytes) else level for level, _, _ in seen])
    warn = [message for (level, message, _), lv in zip(seen, levels) if lv != DiagnosticStatus.OK[0]]
    print(f'{len(warn)} of {len(seen)} reports not OK: {sorted(set(warn))[:5]}')
    assert not np.any(levels == DiagnosticStatus.ERROR[0])
    assert len(warn) <= 0.05 * len(seen)
    turns = [m for (lv, m, _), level in zip(seen, levels) if m.startswith('coasting through a turn')]
    assert turns and all(level == DiagnosticStatus.OK[0] for (_, m, _), level in zip(seen, levels)
                         if m.startswith('coasting through a turn') and ';' not in m)
    assert any(m.startswith('waiting for the still period') for _, m, _ in seen[:20])
    assert any(m.startswith('learning: gate open') for _, m, _ in seen)


def test_the_key_values_carry_their_units(ros):
    node = make_stkf_node()
    node.pubs = {name: Capture() for name in node.pubs}
    _, message, values = node.diagnostic_values()       # before any data
    assert 'inf' not in message and 'nan' not in message.lower()
    assert message.startswith('waiting for the still period: no data yet')
    assert values['temperature_c'] == 'none' and values['temperature_age_s'] == 'no reading yet'
    level, message, values = _drive(node, 120.0)[-1]
    node.destroy_node()
    assert 20.0 < values['temperature_c'] < 40.0                       # degC (the drive: 26 -> 37)
    drift = values['drift_deg_s']
    assert 0.01 < abs(drift) < 1.0                                     # deg/s: this gyro's drift is ~0.1-0.3
    assert drift == pytest.approx(math.degrees(node.estimator.output.latest.d_hat[-1]), rel=1e-9)
    assert 0.0 < values['heading_sigma_deg'] < 10.0 and values['yaw_sigma_deg'] >= values['heading_sigma_deg']
    assert values['since_compass_update_s'] >= 0.0
    for name, unit in (('temperature', 'rad/s/degC'), ('temperature_rate', 'rad/s/(degC/s)'), ('constant', 'rad/s')):
        assert isinstance(values[f'param.{name} [{unit}]'], float) and f'sigma.{name} [{unit}]' in values


def test_a_declared_missing_temperature_sensor_is_ok(ros):
    """Without `imu/temperature` the node learns the constant drift only: WARN unless declared,
    OK with `temperature_sensor: false`."""
    reports = {}
    for declared in (True, False):
        node = make_stkf_node({'temperature_sensor': declared})
        node.pubs = {name: Capture() for name in node.pubs}
        reports[declared] = _drive(node, 150.0, streams=('imu', 'mag'))[5:]     # from 5 s on
        node.destroy_node()
    assert all(level == DiagnosticStatus.WARN and 'no temperature readings' in message
               for level, message, _ in reports[True])
    assert all(level == DiagnosticStatus.OK and 'temperature' not in message.replace('(no temperature sensor)', '')
               for level, message, _ in reports[False])
    assert any(message == 'learning the constant drift only (no temperature sensor)'
               for _, message, _ in reports[False])


def _health(**changes):
    """A node running as designed, learning, 10 min into a drive."""
    from gyro_thermal_comp.nodes.node_health import NodeHealth
    base = dict(imu_received=30000, imu_received_new=50, published_new=50, node_age_s=600.0, started=True,
                gate_open=True, heading_sigma_deg=0.4, temperature_age_s=0.5, imu_for_s=600.0, filter_updates=20)
    return NodeHealth(**{**base, **changes})


OK, WARN, ERROR = 0, 1, 2   # diagnostic_msgs' levels (node_health.py uses the same numbers)


@pytest.mark.parametrize('changes, level, phrase', [
    ({}, OK, 'learning: gate open'),
    ({'gate_open': False, 'gate_reasons': ('turn_rate',)}, OK, 'coasting through a turn or manoeuvre (turn_rate)'),
    ({'gate_open': False, 'gate_reasons': ('field_norm',), 'since_compass_s': 20.0, 'heading_sigma_deg': 0.9},
     OK, 'coasting on the model: field_norm for 20 s'),
    ({'gate_open': False, 'gate_reasons': ('field_norm',), 'since_compass_s': 900.0, 'heading_sigma_deg': 4.2},
     WARN, 'heading uncertain: 1-sigma 4.2 deg after 900 s'),
    ({'not_learning': 'not learning: every window crosses a time gap'}, WARN, 'every window crosses a time gap'),
    ({'temperature_age_s': 30.0}, WARN, 'temperature stale for 30 s'),
    ({'parameter_files': ('parameter file x.yaml: no section applies',)}, WARN, 'no section applies'),
    ({'imu_received': 0, 'node_age_s': 1.0, 'started': False, 'waiting': 'waiting for the still period: no data yet'},
     OK, 'no data yet'),
    ({'imu_received': 0, 'node_age_s': 30.0, 'started': False, 'waiting': 'w'}, ERROR, 'no IMU data on imu/data_raw'),
    ({'heading_sigma_deg': 180.0, 'gate_open': False, 'gate_reasons': ('turn_rate',)}, OK, 'heading unknown'),
    ({'learn': False, 'filter_updates': 0, 'not_learning': None}, OK, 'fixed drift parameters (learn: false)'),
    ({'silent': {'imu': 12.0}}, ERROR, 'IMU silent for 12 s'),
    ({'published_new': 0, 'dropped_new': 50}, ERROR, 'every IMU sample since the last report was dropped'),
])
def test_levels_follow_diagnostic_updater(changes, level, phrase):
    from gyro_thermal_comp.nodes.node_health import assess
    got, message = assess(_health(**changes))
    assert got == level and phrase in message, message
    assert 'inf' not in message
