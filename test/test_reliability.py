"""No input can silence, crash or poison the STKF node. One row per defect: the node (its
core fed in-process, diagnostics as the node publishes them) gets a bundled bag with the fault put
in; every output is finite, diagnostics name the cause, and where the input was garbage the learned
model is exactly what the clean bag gives (the garbage never reached the filter)."""
import math

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus

from conftest import BAGS
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.samples import MagSamples, SensorChunk, TemperatureSamples, concat_chunks, slice_samples
from gyro_thermal_comp.thermal.reasons import REASON_BIT

DURATION_S = 1800.0   # static_ramp: 30 s still, then ~170 learning windows on the heating ramp


@pytest.fixture(scope='module')
def clean():
    chunks = []
    for chunk in read_chunks(BAGS / 'static_ramp', 60.0, streams=['imu', 'mag', 'temperature']):
        if chunk.imu.t[0] >= DURATION_S:
            break
        chunks.append(chunk)
    return concat_chunks(chunks)


def _insert(samples, at_s: float, t_new, **columns):
    """`samples` with rows (stamps t_new, values columns) inserted after the last row before at_s:
    they arrive in between, whatever their stamps say."""
    k = int(np.searchsorted(samples.t, at_s))
    t = np.insert(samples.t, k, t_new)
    values = {name: np.insert(getattr(samples, name), k, v, axis=0) for name, v in columns.items()}
    return type(samples)(t, **values)


def future_imu_stamps(c):
    n = 5
    t = c.imu.t[6000] + 3600.0 + 0.1 * np.arange(n)
    return SensorChunk(imu=_insert(c.imu, 600.0, t, gyro=np.zeros((n, 3)), accel=np.tile([0, 0, 9.8], (n, 1))),
                       mag=c.mag, temperature=c.temperature)


def huge_gyro(c):
    n = 5
    t = c.imu.t[6000] + 0.01 + 0.01 * np.arange(n)
    return SensorChunk(imu=_insert(c.imu, 600.01, t, gyro=np.full((n, 3), 1e30), accel=np.tile([0, 0, 9.8], (n, 1))),
                       mag=c.mag, temperature=c.temperature)


def huge_temperature(c):
    t = c.temperature.t[600] + 0.5 + 0.1 * np.arange(3)
    return SensorChunk(imu=c.imu, mag=c.mag, temperature=_insert(c.temperature, 600.5, t, temp_c=np.full(3, 1e30)))


def temperature_spike(c):
    k = 600
    t = np.array([c.temperature.t[k] + 0.5])
    return SensorChunk(imu=c.imu, mag=c.mag,
                       temperature=_insert(c.temperature, t[0], t, temp_c=c.temperature.temp_c[k:k + 1] + 80.0))


GARBAGE = {  # defect row -> (fault, counter that must name it, how many)
    '1 IMU stamped an hour ahead': (future_imu_stamps, 'core.imu_dropped_jump', 5),
    '4 gyro samples of 1e30': (huge_gyro, 'core.imu_dropped_range', 5),
    '4 temperature of 1e30': (huge_temperature, 'core.temperature_dropped_range', 3),
    '4 one +80 degC temperature sample': (temperature_spike, 'core.temperature_dropped_rate', 1),
}


def _run(chunk: SensorChunk):
    node = make_stkf_node()
    out = node.estimator.process(chunk)
    level, message, values = node.diagnostic_values()
    params = node.estimator.params.copy()
    node.destroy_node()
    return out, level, message, values, params


def _finite(out):
    for col in (out.track.heading_rad, out.track.heading_sigma_rad, out.track.drift_rad_s, out.gyro_compensated):
        assert np.all(np.isfinite(col))


@pytest.mark.parametrize('row', sorted(GARBAGE))
def test_garbage_is_dropped_named_and_never_learned(ros, clean, row):
    fault, counter, count = GARBAGE[row]
    out_clean, *_, params_clean = _run(clean)
    out, level, message, values, params = _run(fault(clean))
    _finite(out)
    assert values[counter] == count, values
    assert level == DiagnosticStatus.WARN and 'input samples dropped' in message
    if counter.startswith('core.imu'):   # each dropped IMU sample still has its output row, flagged
        assert np.count_nonzero(out.reasons & REASON_BIT['dropped_input']) == count
    # the filter never saw the garbage: the same model as from the clean bag (same process, same CPU)
    np.testing.assert_allclose(params, params_clean, rtol=1e-12, atol=0.0)
    assert values['core.windows_used'] > 100


def test_all_zero_magnetometer_from_start_coasts_and_says_why(ros, clean):
    """Defect 2: a dead magnetometer (all zeros) crashed the node (ZeroDivisionError in the gate)."""
    chunk = SensorChunk(imu=clean.imu, mag=MagSamples(clean.mag.t, np.zeros_like(clean.mag.field)),
                        temperature=clean.temperature)
    out, level, message, values, params = _run(chunk)
    _finite(out)
    assert values['core.mag_dropped_range'] == clean.mag.t.size
    assert 'no_compass' in values['gate_reasons'] and 'coasting on the model: no_compass' in message
    assert values['core.windows_used'] == 0 and np.all(np.isfinite(params))


def test_temperature_dropout_stops_learning_and_grows_uncertainty(ros, clean):
    """Defect 8: a 10 min temperature dropout was silent and learning went on with a stale temperature."""
    t = clean.temperature.t
    gone = (t >= 900.0) & (t < 1500.0)
    chunk = SensorChunk(imu=clean.imu, mag=clean.mag,
                        temperature=TemperatureSamples(t[~gone], clean.temperature.temp_c[~gone]))
    node = make_stkf_node()
    during = node.estimator.process(_until(chunk, 1400.0))
    level, message, values = node.diagnostic_values()
    assert level == DiagnosticStatus.WARN and 'temperature stale' in message and values['temperature_age_s'] > 400.0
    used_at_1400 = values['core.windows_used']
    last_reading = t[t < 900.0][-1]
    stale = during.track.t > last_reading + node.estimator.cfg.temperature_timeout_s
    assert np.all(during.reasons[stale] & REASON_BIT['temperature_stale'])
    assert np.all(np.isfinite(during.temperature_c[~stale]))
    sigma = during.track.heading_sigma_rad[stale]
    node2 = make_stkf_node()
    clean_sigma = node2.estimator.process(_until(clean, 1400.0)).track.heading_sigma_rad[stale]
    node2.destroy_node()
    assert np.mean(sigma) > np.mean(clean_sigma)          # the held temperature's uncertainty is counted
    node3 = make_stkf_node()   # no window after the readings stopped was learned
    node3.estimator.process(_until(chunk, last_reading + node.estimator.cfg.temperature_timeout_s))
    assert used_at_1400 == node3.estimator.counters()['windows_used']
    node3.destroy_node()
    after = node.estimator.process(_from(chunk, 1400.0))
    _finite(after)
    level, message, values = node.diagnostic_values()
    assert 'temperature stale' not in message and values['core.windows_used'] > used_at_1400 + 20
    node.destroy_node()


def test_a_clock_that_jumps_back_is_a_new_time_base(ros, clean):
    """A bag played in a loop / a simulator reset: the later stamps are 850 s earlier. The node keeps
    its model, treats the jump as a time gap, and goes on learning (it used to drop everything)."""
    def back(s, **cols):
        t = np.where(s.t >= 900.0, s.t - 850.0, s.t)
        return type(s)(t, **cols)
    c = clean
    chunk = SensorChunk(imu=back(c.imu, gyro=c.imu.gyro, accel=c.imu.accel), mag=back(c.mag, field=c.mag.field),
                        temperature=back(c.temperature, temp_c=c.temperature.temp_c))
    out, level, message, values, params = _run(chunk)
    _finite(out)
    assert values['core.time_base_changes'] == 1 and values['core.imu_time_base_changes'] == 1
    valid_after = out.valid[c.imu.t >= 900.0]
    assert np.count_nonzero(~valid_after) <= 10          # only the samples that confirmed the jump
    assert values['core.windows_used'] > 120


def _until(chunk, t_s):
    return SensorChunk(**{k: slice_samples(s, s.t < t_s) for k, s in chunk.streams().items()})


def _from(chunk, t_s):
    return SensorChunk(**{k: slice_samples(s, s.t >= t_s) for k, s in chunk.streams().items()})


def test_huge_state_file_is_refused_by_the_model(ros):
    """Defect 5: x = 1e300 crash-looped the node. The model refuses what the gyro could never measure."""
    node = make_stkf_node()
    names = node.estimator.model.names
    with pytest.raises(ValueError, match='beyond the gyro range'):
        node.estimator.set_state({'terms': list(names), 'x': [1e300] + [0.0] * (len(names) - 1)})
    assert math.isfinite(node.estimator.params[0])
    node.destroy_node()


def test_live_node_rides_through_future_stamps_and_a_dead_magnetometer():
    """Defects 1 and 2, live: the node in its own process (as `ros2 run` starts it), fed by an
    independent rclpy publisher. Five IMU messages stamped an hour ahead and 5 s of an all-zero
    magnetometer: every other IMU sample still gets its output, /diagnostics names both causes, and
    the node exits 0 on Ctrl-C."""
    import signal
    import subprocess
    import sys
    import threading
    import time

    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu, MagneticField, Temperature
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Header
    from gyro_thermal_comp.nodes import conversions as conv

    chunk = next(read_chunks(BAGS / 'vehicle_loop', 40.0, streams=['imu', 'mag', 'temperature']))
    proc = subprocess.Popen([sys.executable, '-m', 'gyro_thermal_comp.nodes.stkf_node', '--ros-args',
                             '-p', 'reliable_inputs:=true', '-p', 'max_latency_s:=60.0',
                             '-p', 'first_sample_wait_s:=60.0', '-p', 'input_queue_depth:=10000',
                             '-p', 'diagnostics_period_s:=0.2'],
                            stderr=subprocess.PIPE, text=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('gtc_fault_player', context=context)
    qos = QoSProfile(depth=5000)
    pubs = {'imu': node.create_publisher(Imu, 'imu/data_raw', qos),
            'mag': node.create_publisher(MagneticField, 'imu/mag', qos),
            'temperature': node.create_publisher(Temperature, 'imu/temperature', qos)}
    outputs, diagnostics = [], {}
    node.create_subscription(Imu, 'imu/data', outputs.append, QoSProfile(depth=5000))
    node.create_subscription(DiagnosticArray, '/diagnostics',
                             lambda m: diagnostics.update({kv.key: kv.value for kv in m.status[0].values},
                                                          message=m.status[0].message), QoSProfile(depth=10))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()

    def wait(condition, what, timeout_s=60.0, alive=True):
        end = time.monotonic() + timeout_s
        while not condition():
            assert not alive or proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < end, f'{what} within {timeout_s} s; diagnostics: {diagnostics}'
            time.sleep(0.05)
    try:
        wait(lambda: all(p.get_subscription_count() for p in pubs.values())
             and all(int(diagnostics.get(f'input.{s}_publishers', 0)) > 0 for s in pubs), 'inputs matched')
        events = sorted([(float(t), s, i) for s in pubs for i, t in enumerate(getattr(chunk, s).t)])
        n_imu = zero_mag = 0
        for t, stream, i in events:
            header = Header(stamp=conv.time_msg(t), frame_id='imu_link')
            if stream == 'imu':
                pubs['imu'].publish(conv.imu_msg(header, chunk.imu.gyro[i], chunk.imu.accel[i]))
                n_imu += 1
                if i == 1000:    # 20 s in: five messages stamped an hour ahead
                    for k in range(5):
                        future = Header(stamp=conv.time_msg(t + 3600.0 + 0.02 * k), frame_id='imu_link')
                        pubs['imu'].publish(conv.imu_msg(future, chunk.imu.gyro[i], chunk.imu.accel[i]))
            elif stream == 'mag':
                msg = MagneticField(header=header)
                dead = 30.0 <= t - chunk.imu.t[0] < 35.0
                zero_mag += dead
                field = np.zeros(3) if dead else chunk.mag.field[i]
                msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = map(float, field)
                pubs['mag'].publish(msg)
            else:
                pubs['temperature'].publish(Temperature(header=header, temperature=float(chunk.temperature.temp_c[i])))
            if stream == 'imu' and n_imu % 200 == 0:
                time.sleep(0.05)   # about 4x real time
        wait(lambda: int(diagnostics.get('input.imu_received', 0)) >= n_imu + 5, 'every sample received')
        wait(lambda: int(diagnostics.get('core.imu_dropped_jump', 0)) == 5
             and int(diagnostics.get('core.mag_dropped_range', 0)) == zero_mag, 'the causes named')
        assert int(diagnostics['input_samples_dropped']) == 5 + zero_mag    # nothing else was dropped
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60.0) == 0
        wait(lambda: len(outputs) >= n_imu, 'every output delivered', timeout_s=20.0, alive=False)
    finally:
        if proc.poll() is None:
            proc.kill()
        executor.shutdown(timeout_sec=2.0)
        rclpy.try_shutdown(context=context)
    assert len(outputs) == n_imu
    for m in outputs:
        assert math.isfinite(m.angular_velocity.z) and math.isfinite(m.orientation.w)


def test_a_state_file_the_model_refuses_is_moved_aside_and_named(ros, tmp_path):
    """Defects 5 and 7 at the node: a huge (x = 1e300) or mismatched state file means a cold start, the
    file moved aside untouched, the reason in /diagnostics; a second node cannot take the same file."""
    import json

    from gyro_thermal_comp.nodes.ros_params import ParameterFileError
    from gyro_thermal_comp.nodes.state_store import FORMAT
    names = list(make_stkf_node().estimator.model.names)
    for x, terms, why in (([1e300] + [0.0] * (len(names) - 1), names, 'beyond the gyro range'),
                          ([0.0], ['constant'], 'do not match')):
        path = tmp_path / 'state.json'
        text = json.dumps({'format': FORMAT, 'terms': terms, 'temperature_ref_c': 25.0, 'x': x})
        path.write_text(text)
        node = make_stkf_node({'state_file': str(path)})
        level, message, values = node.diagnostic_values()
        assert level == DiagnosticStatus.WARN and 'state file rejected' in message
        assert why in values['state_file'] and 'moved aside' in values['state_file']
        moved = [p for p in tmp_path.iterdir() if p.name.startswith('state.json.rejected-')]
        assert any(p.read_text() == text for p in moved) and not path.exists()
        with pytest.raises(ParameterFileError, match='state_file'):
            make_stkf_node({'state_file': str(path)})
        node.destroy_node()


def test_warm_started_parameters_show_during_the_still_period(ros, tmp_path):
    """Defect 13: during the still period diagnostics showed 0 for warm-started parameters."""
    import json

    from gyro_thermal_comp.nodes.state_store import FORMAT
    names = list(make_stkf_node().estimator.model.names)
    x = [1e-4, 2e-3, 1e-3, 1e-6][:len(names)] + [0.0] * max(0, len(names) - 4)
    (tmp_path / 's.json').write_text(json.dumps({'format': FORMAT, 'terms': names, 'temperature_ref_c': 25.0, 'x': x}))
    node = make_stkf_node({'state_file': str(tmp_path / 's.json')})
    _, message, values = node.diagnostic_values()
    assert 'waiting for the still period' in message
    assert float(values['param.temperature [rad/s/degC]']) == pytest.approx(x[0]) and values['state_file'].startswith('warm start')
    node.destroy_node()


def test_no_temperature_topic_is_never_reported_ok(ros, clean):
    """A node that never gets a temperature must say so from the still period on, and never
    report OK 'learning' (it learns the constant drift only, at the reference temperature)."""
    node = make_stkf_node()
    seen = []
    for t0 in np.arange(0.0, 120.0, 5.0):
        node.process_chunk(SensorChunk(imu=slice_samples(clean.imu, (clean.imu.t >= t0) & (clean.imu.t < t0 + 5.0)),
                                       mag=slice_samples(clean.mag, (clean.mag.t >= t0) & (clean.mag.t < t0 + 5.0))))
        level, message, _ = node.diagnostic_values()
        seen.append((t0, level, message))
    node.destroy_node()
    assert all(level == DiagnosticStatus.WARN and 'no temperature readings' in message
               for t0, level, message in seen if t0 >= 5.0), seen
    assert seen[1][2].startswith('waiting for the still period to end')
    assert seen[-1][2].startswith('learning the constant drift only')
