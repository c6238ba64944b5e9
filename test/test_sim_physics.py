"""Physics of the simulator: each test checks a law the data must obey, not a shape."""
import allantools
import numpy as np
import pytest

from gyro_thermal_comp.angles import euler_from_quat, rotation_matrix_from_quat, wrap_angle, yaw_from_quat
from gyro_thermal_comp.constants import EARTH_RATE_RAD_S
from gyro_thermal_comp.samples import concat_chunks
from gyro_thermal_comp.sim import covariances, make_config, simulate
from gyro_thermal_comp.sim.earth import earth_rate_enu
from gyro_thermal_comp.sim.engine import build_world
from gyro_thermal_comp.sim.mounts import HORIZONTAL_AXIS, rot_z

QUIET = {'rate_random_walk': 0.0, 'bias_instability': 0.0}


def run(scenario, **kw):
    cfg = make_config(scenario, **kw)
    return cfg, concat_chunks(simulate(cfg))


def noise_sigma(cfg):
    return np.radians(cfg.params['gyro_noise_dps_rthz']) * np.sqrt(cfg.imu_rate_hz)


def test_static_gyro_mean_is_the_true_drift():
    cfg, ch = run('static_ramp', seed=4, duration_s=300)
    err = ch.imu.gyro - ch.gyro_bias.vec            # sensor = body, true rate 0
    n = len(err)
    assert np.all(np.abs(err.mean(0)) < 4 * noise_sigma(cfg) / np.sqrt(n))
    np.testing.assert_allclose(err.var(0), covariances(cfg).gyro_rad2_s2, rtol=0.05)   # what bags declare
    # and the drift is not trivially zero: it holds the turn-on bias (tenths of deg/s) and Earth rate
    assert np.all(np.abs(ch.gyro_bias.vec.mean(0)) > np.radians(1e-3))


def test_null_drift_is_exactly_the_paper_model_plus_earth_rate():
    cfg, ch = run('null', seed=2, duration_s=1500, imu_rate_hz=20)
    u = cfg.unit
    temp, dtemp = build_world(cfg).profile(ch.gyro_bias.t)
    assert np.ptp(temp) > 5 and np.ptp(dtemp) > 0.005       # the ramp is under way
    model = np.radians(np.outer(temp, u.gyro_a_dps_per_c) + np.outer(dtemp, u.gyro_b_dps_per_c_per_s) + u.gyro_c_dps)
    rot = rotation_matrix_from_quat(ch.odom.quat)
    earth = np.einsum('nji,j->ni', rot, earth_rate_enu(np.radians(cfg.params['latitude_deg'])))
    np.testing.assert_allclose(ch.gyro_bias.vec, model + earth, rtol=0, atol=1e-15)
    assert abs(earth[0, 2] - EARTH_RATE_RAD_S * np.sin(np.radians(50))) < 2e-6   # ~1 deg tilt, 50 N
    # the temperature sensor reads the same temperature, only quantised (no lag, no noise in null)
    t_read = build_world(cfg).profile(ch.temperature.t)[0]
    assert np.max(np.abs(ch.temperature.temp_c - t_read)) <= cfg.preset.temp.lsb_c / 2 + 1e-12


def test_rectangle_lap_closes_to_two_pi():
    flat = {'roll_gain_deg_per_mps2': 0.0, 'pitch_gain_deg_per_mps2': 0.0}
    for params, tol in ((flat, 1e-9), (None, 2e-3)):
        cfg, ch = run('vehicle_loop', duration_s=400, imu_rate_hz=50, mag_rate_hz=5, temp_rate_hz=1,
                      params=params)
        m = build_world(cfg).motion
        t = ch.odom.t
        i0, i1 = np.searchsorted(t, [m.lap_start_s, m.lap_start_s + m.lap_period_s])
        assert t[i0] == m.lap_start_s and t[i1] == m.lap_start_s + m.lap_period_s
        rz = ch.odom.rate_body[i0:i1 + 1, 2]
        assert abs(np.trapezoid(rz, t[i0:i1 + 1]) - 2 * np.pi) < tol
        yaw = np.unwrap(yaw_from_quat(ch.odom.quat))
        assert abs(yaw[i1] - yaw[i0] - 2 * np.pi) < 1e-9
        assert np.linalg.norm(ch.odom.position[i1] - ch.odom.position[i0]) < 1e-6
        assert np.linalg.norm(ch.odom.position[i0 + 1000] - ch.odom.position[i0]) > 10   # it did drive
        # the yaw rate drives the centripetal force: accel y ~ v * r in the turns (level, noise aside)
        v = ch.odom.velocity_body[:, 0]
        turn = ch.odom.rate_body[:, 2] > 0.3
        lat = ch.imu.accel[turn, 1] - cfg.unit.accel_bias_m_s2[1]
        assert np.allclose(lat, (v * ch.odom.rate_body[:, 2])[turn], atol=0.25)


def test_vehicle_gyro_minus_truth_bias_is_the_true_rate_plus_white_noise():
    cfg, ch = run('vehicle_loop', seed=1, duration_s=400)
    res = ch.imu.gyro - ch.gyro_bias.vec - ch.odom.rate_body
    sigma = noise_sigma(cfg)
    assert np.all(np.abs(res.mean(0)) < 4 * sigma / np.sqrt(len(res)))
    assert np.allclose(res.std(0), sigma, rtol=0.03)
    # the truth carries the rate-proportional errors too (scale factor ~1 %): it grows in the turns
    slope = np.polyfit(ch.odom.rate_body[:, 2], ch.gyro_bias.vec[:, 2], 1)[0]
    assert abs(slope) > 0.5 * abs(cfg.unit.gyro_scale_factor[2])


@pytest.mark.parametrize('spin_hz', [0.5, 4.0])
def test_carousel_rates_rotate_with_the_encoder_angle(spin_hz):
    # constant temperature and no random bias: the x/y truth bias is then a constant plus Earth rate
    cfg, ch = run('carousel_horizontal', seed=3, duration_s=120,
                  params={'spin_hz': spin_hz, 'temp_peak_c': 25.0},
                  effects={**QUIET, 'g_sensitivity': 0, 'scale_factor': 0, 'cross_axis': 0})
    th = ch.joint.position
    spinning = ch.joint.t > cfg.params['still_s'] + cfg.params['spinup_s']
    # spin rate on the axial gyro equals the joint velocity (truth rate = gyro - bias, noise aside)
    axial = ch.imu.gyro[:, 2] - ch.gyro_bias.vec[:, 2]
    assert np.max(np.abs(axial - ch.joint.velocity)) < 6 * noise_sigma(cfg)
    assert abs(ch.joint.velocity[spinning].mean() - 2 * np.pi * spin_hz) < 1e-9
    # Earth rate in the mount frame, seen in the sensor frame through the encoder angle
    base = rotation_matrix_from_quat(ch.odom.quat[0])
    e_m = HORIZONTAL_AXIS.T @ base.T @ earth_rate_enu(np.radians(cfg.params['latitude_deg']))
    e_s = np.einsum('nji,j->ni', rot_z(th), e_m)
    resid = ch.gyro_bias.vec[:, :2] - e_s[:, :2]
    resid -= resid.mean(0)
    assert np.max(np.abs(resid)) < 3e-3 * np.linalg.norm(e_m[:2])     # encoder quantisation only
    assert np.ptp(ch.gyro_bias.vec[spinning, 0]) > 1.5 * np.linalg.norm(e_m[:2])   # it is modulated


def test_wheel_spin_follows_the_speed_and_stops_with_the_car():
    cfg, ch = run('carousel_wheel', duration_s=300)
    p = cfg.params
    rate = ch.joint.velocity
    speed = np.linalg.norm(ch.odom.velocity_body, axis=1)
    straight = np.abs(ch.odom.rate_body[:, 2]) < 1e-9
    np.testing.assert_allclose(rate[straight], speed[straight] / p['wheel_radius_m'], atol=1e-9)
    assert rate.max() > 0.9 * p['speed_mps'] / p['wheel_radius_m']
    stopped = (ch.odom.t > p['still_s'] + 5) & (speed == 0)
    assert stopped.any() and np.all(rate[stopped] == 0)
    axial = ch.imu.gyro[:, 2] - ch.gyro_bias.vec[:, 2]
    body_y = ch.odom.rate_body[:, 1]          # the axle is body y: the pitch rate adds to the spin
    assert np.max(np.abs(axial - rate - body_y)) < 6 * noise_sigma(cfg)


def _mag_heading(cfg, ch, roll, pitch):
    """Tilt-compensated ENU yaw from the magnetometer (declination applied)."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    m = ch.mag.field
    bx = cp * m[:, 0] + sp * sr * m[:, 1] + sp * cr * m[:, 2]
    by = cr * m[:, 1] - sr * m[:, 2]
    return np.pi / 2 - np.radians(cfg.params['declination_deg']) - np.arctan2(by, bx)


@pytest.mark.parametrize('deviation_ut', [0.0, 3.0])
def test_compass_heading_matches_true_yaw_within_the_deviation(deviation_ut):
    cfg, ch = run('vehicle_loop', seed=5, duration_s=450, effects={'compass_deviation': deviation_ut})
    stride = round(cfg.truth_rate_hz / cfg.mag_rate_hz)
    idx = np.arange(len(ch.mag.t)) * stride
    assert np.array_equal(ch.odom.t[idx], ch.mag.t)
    roll, pitch, yaw = euler_from_quat(ch.odom.quat[idx])
    clean = np.all(ch.mag_disturbance.vec[idx] == 0, axis=1)
    assert (~clean).any()                                    # an interference episode is in the run
    err = np.abs(wrap_angle(_mag_heading(cfg, ch, roll, pitch) - yaw))[clean]
    f = cfg.params['field_ut']
    b_h = f * np.cos(np.radians(cfg.params['dip_deg']))
    u = cfg.unit
    dev = np.linalg.norm(u.mag_hard_iron_ut) + np.linalg.norm(u.mag_soft_iron - np.eye(3), 2) * f
    bound = np.arcsin(min(1.0, (dev + 6 * cfg.preset.mag.noise_ut) / b_h))
    assert err.max() < bound
    if deviation_ut:                                         # the deviation is visible, heading-dependent
        h_xy = np.linalg.norm(u.mag_hard_iron_ut[:2])
        assert err.max() > 0.5 * np.arcsin(h_xy / b_h)


def test_static_compass_with_accel_tilt_compensation():
    cfg, ch = run('static_ramp', seed=6, duration_s=120, effects={'compass_deviation': 0})
    a = ch.imu.accel.mean(0)
    roll, pitch = np.arctan2(a[1], a[2]), np.arctan2(-a[0], np.hypot(a[1], a[2]))
    yaw_true = yaw_from_quat(ch.odom.quat[0])
    err = wrap_angle(np.mean(_mag_heading(cfg, ch, roll, pitch)) - yaw_true)
    # accel bias (<= 5 mg) tilts the compensation by < 0.3 deg, amplified by tan(dip) ~ 2.25
    assert abs(err) < np.radians(1.0)


def test_allan_deviation_at_one_second_is_the_configured_arw():
    cfg, ch = run('static_ramp', seed=7, duration_s=900)
    (tau,), (adev,), *_ = allantools.oadev(ch.imu.gyro[:, 2], rate=cfg.imu_rate_hz, data_type='freq',
                                            taus=[1.0])
    assert tau == 1.0
    assert abs(adev / np.radians(cfg.params['gyro_noise_dps_rthz']) - 1) < 0.10


def test_mlr_leaves_structured_residual_but_not_on_null():
    """The richer truth defeats one global a*T + b*dT/dt + c fit (paper: +-15 deg); null does not."""
    out = {}
    for scenario in ('static_ramp', 'null'):
        cfg, ch = run(scenario, seed=0, imu_rate_hz=5, mag_rate_hz=1, temp_rate_hz=5)
        temp, dtemp = build_world(cfg).profile(ch.gyro_bias.t)
        d = np.degrees(ch.gyro_bias.vec[:, 2])
        a = np.column_stack([temp, dtemp, np.ones_like(temp)])
        r = d - a @ np.linalg.lstsq(a, d, rcond=None)[0]
        out[scenario] = np.sqrt(np.mean(r ** 2)), np.ptp(np.cumsum(r) / cfg.imu_rate_hz)
    rms, span = out['static_ramp']
    assert 2e-3 < rms < 2e-2 and 5 < span < 60          # deg/s, deg
    assert out['null'][0] < 1e-9


def test_effect_signatures():
    """Toggling one effect changes the truth by exactly its documented term (same seed, same unit)."""
    base = {**QUIET, 'thermal_lag': 0.0}
    kw = dict(seed=8, duration_s=400, imu_rate_hz=50)
    cfg0, c0 = run('vehicle_loop', effects={**base, 'thermal_curvature': 0, 'scale_factor': 0,
                                            'g_sensitivity': 0}, **kw)
    temp = build_world(cfg0).profile(c0.gyro_bias.t)[0]
    rot = rotation_matrix_from_quat(c0.odom.quat)
    w_is = c0.odom.rate_body + np.einsum('nji,j->ni', rot, earth_rate_enu(np.radians(50)))

    cfg, c = run('vehicle_loop', effects={**base, 'thermal_curvature': 1e-4, 'scale_factor': 0,
                                          'g_sensitivity': 0}, **kw)
    expect = np.radians(np.outer((temp - 25) ** 2, cfg.unit.gyro_curvature_dps_per_c2))
    np.testing.assert_allclose(c.gyro_bias.vec - c0.gyro_bias.vec, expect, atol=1e-15)
    assert abs(cfg.unit.gyro_curvature_dps_per_c2[2]) == 1e-4

    cfg, c = run('vehicle_loop', effects={**base, 'thermal_curvature': 0, 'scale_factor': 0.02,
                                          'g_sensitivity': 0}, **kw)
    np.testing.assert_allclose(c.gyro_bias.vec - c0.gyro_bias.vec, w_is * cfg.unit.gyro_scale_factor,
                               atol=1e-15)

    cfg, c = run('vehicle_loop', effects={**base, 'thermal_curvature': 0, 'scale_factor': 0,
                                          'g_sensitivity': 0.05}, **kw)
    force = c.imu.accel - cfg.unit.accel_bias_m_s2       # noisy but unbiased specific force
    g_term = np.degrees(c.gyro_bias.vec - c0.gyro_bias.vec)   # deg/s
    fit = np.linalg.lstsq(force / 9.80665, g_term, rcond=None)[0].T
    np.testing.assert_allclose(fit, cfg.unit.gyro_g_sensitivity_dps_per_g, atol=2e-4)

    # time_offset of one IMU period: the IMU carries the physics one sample earlier
    dt = 1 / 50
    cfg, c = run('vehicle_loop', effects={**base, 'thermal_curvature': 0, 'scale_factor': 0,
                                          'g_sensitivity': 0, 'time_offset': dt}, **kw)
    w = c0.odom.rate_body
    np.testing.assert_allclose(c.gyro_bias.vec[1:], c0.gyro_bias.vec[:-1] + w[:-1] - w[1:], atol=1e-12)


def test_a_run_without_a_still_start_simulates():
    """still_s = 0 (allowed by its range) used to put two temperature knots at t = 0."""
    cfg, ch = run('carousel_vertical', duration_s=60.0, params={'still_s': 0.0})
    assert ch.imu.t.size > 0 and np.all(np.isfinite(ch.imu.gyro))
