"""Issue 16 item 2: the orientation covariance the STKF node publishes is honest (REP 145).

On bundled bags with ground truth, |error| <= 2 sigma for at least 90 % of the truth samples, for
roll, pitch and yaw each; and the sigmas are not inflated to get there (median 2 sigma under stated
bounds), so each test can fail both ways. The variances are those of the node's own code path
(OrientationVariance.from_params, the estimator built from the node's parameter defaults); a short
test checks that the node's messages carry exactly them.
"""
import json
import math

import numpy as np
import pytest

from conftest import BAGS, Capture
from gyro_thermal_comp.angles import euler_from_quat, wrap_angle
from gyro_thermal_comp.bag_io import BagReader, read_chunks
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.nodes.orientation_uncertainty import OrientationVariance, TiltScatter
from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
from gyro_thermal_comp.stamps import ns_at
from gyro_thermal_comp.thermal.compensator import ThermalCompensator

COVERAGE = 0.90
TILT_2SIGMA_MAX_DEG = 3.0          # median 2 sigma of roll and pitch
YAW_2SIGMA_MAX_DEG = 8.0           # ... of yaw, declination known (compass deviation 3 deg, model 0.5 deg)
YAW_2SIGMA_UNKNOWN_MAX_DEG = 25.0  # ... declination left unset (10 deg assumed)


def _declination_rad(bag) -> float:
    """The local declination a robot team would look up (a field model); here the simulator's."""
    with BagReader(bag) as reader:
        return math.radians(json.loads(next(iter(reader.text('/sim/config'))))['params']['declination_deg'])


def _compensator(values):
    """What the node runs (estimator + fast path) with the node's own variances."""
    cfg = config_from_params(values)
    variance = OrientationVariance.from_params(values, cfg)
    comp = ThermalCompensator(cfg, values['output_delay_s'], held=lambda out, chunk: variance.held_tilt(
        out, chunk.imu.accel, comp.estimator.gyro.tilt_max_rate_rad_s))
    return comp, variance


def _published(comp, variance, out):
    """Stamps (ns) and roll, pitch, yaw with their variances, as the node publishes them."""
    h = out.held
    return np.column_stack((out.ns, h['roll'], h['pitch'], out.heading, h['roll_var'], h['pitch_var'],
                            variance.yaw_variance(out.heading_var)))[out.ok]


def _errors_and_sigmas(bag, **params):
    """Roll, pitch, yaw errors of the published orientation against /ground_truth/odom and the
    published 1-sigmas, rad (N, 3) each."""
    values = {s.name: s.default for s in all_specs()} | params
    comp, variance = _compensator(values)
    rows, truth = [], []
    with BagReader(bag) as reader:
        origin = reader.time_origin_ns
        for chunk in reader.chunks(60.0, streams=['imu', 'mag', 'temperature', 'odom']):
            if chunk.odom is not None:
                truth.append(np.column_stack((ns_at(chunk.odom.t, origin), *euler_from_quat(chunk.odom.quat))))
            out = comp.run(chunk, origin)
            if out is not None:
                rows.append(_published(comp, variance, out))
    rows, truth = np.concatenate(rows), np.concatenate(truth)
    k = np.searchsorted(rows[:, 0], truth[:, 0])
    k, truth = k[k < len(rows)], truth[k < len(rows)]
    same = rows[k, 0] == truth[:, 0]                       # truth stamps are IMU stamps
    assert np.count_nonzero(same) > 0.9 * len(truth)
    k, truth = k[same], truth[same]
    return wrap_angle(rows[k, 1:4] - truth[:, 1:4]), np.sqrt(rows[k, 4:7])


def _check(err, sigma, yaw_bound_deg, label):
    report = []
    for i, (axis, bound) in enumerate((('roll', TILT_2SIGMA_MAX_DEG), ('pitch', TILT_2SIGMA_MAX_DEG),
                                       ('yaw', yaw_bound_deg))):
        covered = float(np.mean(np.abs(err[:, i]) <= 2 * sigma[:, i]))
        two_sigma = math.degrees(2 * float(np.median(sigma[:, i])))
        report.append(f'{axis}: {100 * covered:.1f} % within 2 sigma, median 2 sigma {two_sigma:.2f} deg')
        assert covered >= COVERAGE and two_sigma < bound, '; '.join(report)
    print(f'{label}: ' + '; '.join(report))     # pytest -rP shows the measured coverage


@pytest.mark.parametrize('declination', ['set', 'unset'])
def test_vehicle_loop_orientation_sigmas_cover_the_truth(declination):
    """Before issue 16: roll/pitch 1 sigma 0.0006 deg against 0.35 deg rms error, yaw 0.18 deg against
    a 2.3 deg offset. Unset, the declination (7 deg here) is unknown and the yaw sigma says so."""
    params = {'declination_rad': _declination_rad(BAGS / 'vehicle_loop')} if declination == 'set' else {}
    err, sigma = _errors_and_sigmas(BAGS / 'vehicle_loop', **params)
    _check(err, sigma, YAW_2SIGMA_MAX_DEG if declination == 'set' else YAW_2SIGMA_UNKNOWN_MAX_DEG,
           f'vehicle_loop, declination {declination}')
    assert np.sqrt(np.mean(np.degrees(err[:, :2]) ** 2)) > 0.1    # the truth comparison is not trivial


@pytest.mark.parametrize('name', ['static_ramp', 'static_ramp_outages'])
def test_static_bags_orientation_sigmas_cover_the_truth(name):
    """2 h at 10 Hz, heated and cooled; with three magnetic outages, during which the yaw sigma grows
    while the gyro coasts."""
    err, sigma = _errors_and_sigmas(BAGS / name, declination_rad=_declination_rad(BAGS / name))
    _check(err, sigma, YAW_2SIGMA_MAX_DEG, f'{name}, declination set')


def test_tilt_scatter_does_not_depend_on_chunking():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 400.0, 0.02)
    accel = np.column_stack((2.0 * np.sin(t / 7.0), 0.3 * rng.standard_normal(t.size), np.full(t.size, 9.8)))
    use = rng.random(t.size) > 0.1
    whole = np.column_stack(TiltScatter(120.0).update(t, accel, use))
    scatter, parts, i = TiltScatter(120.0), [], 0
    while i < t.size:
        n = int(rng.integers(1, 700))
        parts.append(np.column_stack(scatter.update(t[i:i + n], accel[i:i + n], use[i:i + n])))
        i += n
    assert np.array_equal(np.concatenate(parts), whole)
    assert np.all(whole[-1] > 0)          # a moving vehicle: the mean has a standard error


def test_the_node_publishes_these_variances(ros):
    node = make_stkf_node()
    node.pubs = {name: Capture() for name in node.pubs}
    values = {s.name: s.default for s in all_specs()}
    comp, variance = _compensator(values)
    expected = []
    for chunk in read_chunks(BAGS / 'vehicle_loop', 10.0, streams=['imu', 'mag', 'temperature']):
        if chunk.imu.t[0] >= 200.0:
            break
        node.process_chunk(chunk)
        out = comp.run(chunk, node.time_origin.ns or 0)
        if out is not None:
            expected.append(_published(comp, variance, out)[:, 4:])
    expected = np.concatenate(expected)
    imu, heading = node.pubs['imu'].msgs, node.pubs['heading'].msgs
    node.destroy_node()
    assert len(imu) == len(heading) == len(expected)
    published = np.array([np.array(m.orientation_covariance)[[0, 4, 8]] for m in imu])
    np.testing.assert_array_equal(published, expected)
    np.testing.assert_array_equal([h.pose.covariance[35] for h in heading], expected[:, 2])
    floor_tilt, floor_yaw = math.radians(0.5) ** 2, math.radians(math.hypot(3.0, 10.0)) ** 2
    assert np.all(published[:, :2] >= floor_tilt) and np.all(published[:, 2] >= floor_yaw)
    assert np.max(published[:, 1]) > 2 * floor_tilt      # the car's accelerations widen pitch
