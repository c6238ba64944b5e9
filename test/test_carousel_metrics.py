"""The paper's error-growth measures (Table 3 shape) and the residuals carouseling leaves."""
import numpy as np
import pytest

from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator
from gyro_thermal_comp.evaluation.carousel_metrics import (HORIZONTAL_X_CAROUSEL_TO_BODY, TABLE3_COLUMNS, error_growth,
                                                           format_table3, integrated_error_growth, record_errors,
                                                           table3_synthetic, unremoved_residuals)
from gyro_thermal_comp.carousel.synthetic import simulate, spin_rate_profile
from gyro_thermal_comp.samples import ImuSamples

G = 9.80665


def test_error_growth_closed_form_and_integrated_agree():
    dw, da = np.array([1e-3, -2e-3, 5e-4]), np.array([0.05, -0.02, 0.01])
    e = error_growth(dw, da, 300.0)
    np.testing.assert_allclose(e['eps_rad'], dw * 300)
    np.testing.assert_allclose(e['dv_m_s'], da * 300 + dw * 9.81 * 300 ** 2 / 2)
    np.testing.assert_allclose(e['ds_m'], da * 300 ** 2 / 2 + dw * 9.81 * 300 ** 3 / 6)
    t = np.linspace(0, 300, 30001)
    ei = integrated_error_growth(t, np.tile(dw, (len(t), 1)), np.tile(da, (len(t), 1)))
    for k in e:
        np.testing.assert_allclose(ei[k][-1], e[k], rtol=1e-6)
    # paper's Table 3, static X: eps 16.35 deg at 300 s <=> dw = 9.5e-4 rad/s
    assert np.degrees(error_growth(np.radians(16.35) / 300, 0.0)['eps_rad']) == pytest.approx(16.35)


def test_table3_from_the_demodulator_improves_inplane_axes_only():
    bg, ba = np.array([9.5e-4, -3.1e-3, 3.3e-4]), np.array([0.05, -0.04, 0.02])
    table, errors = table3_synthetic(bg, ba, spin_hz=0.5, duration_s=40.0)
    assert tuple(table) == TABLE3_COLUMNS
    for col in TABLE3_COLUMNS:
        assert set(table[col]) == {'eps_rad', 'dv_m_s', 'ds_m'}
        assert all(v.shape == (3,) for v in table[col].values())
    st, ve, ho = (table[c]['eps_rad'] for c in TABLE3_COLUMNS)
    np.testing.assert_allclose(st, bg * 300)
    # vertical axis: body x, y modulated away; z (spin axis) as bad as static
    assert np.all(np.abs(ve[:2]) < 1e-6 * np.abs(st[:2]))
    assert ve[2] == pytest.approx(st[2], rel=1e-6)
    # horizontal axis along body x: x carries the sensor's axial bias, y and z are modulated
    assert ho[0] == pytest.approx(bg[2] * 300, rel=1e-6)
    assert np.all(np.abs(ho[1:]) < 1e-6 * np.abs(st[1:]))
    dv_ve = table['vertical_axis']['dv_m_s']
    assert np.all(np.abs(dv_ve[:2]) < 1e-5 * np.abs(table['static']['dv_m_s'][:2]))
    text = format_table3(table)
    assert 'eps [deg]' in text and len(text.splitlines()) == 10


def _run(chunk, **cfg):
    return CarouselDemodulator(CarouselConfig(**cfg)).update(chunk).records


def test_scale_factor_residual_matches_prediction_and_is_reported_separately():
    s = 0.004                                                # +0.4 % axial scale factor
    spin = 2 * np.pi * 2.0
    chunk, _ = simulate(10.0, 100.0, spin_rate_profile(2.0), encoder_hz=100.0)
    g = chunk.imu.gyro.copy()
    g[:, 2] *= 1 + s
    recs = _run(chunk.with_streams(imu=ImuSamples(chunk.imu.t, g, chunk.imu.accel)))
    dw, _ = record_errors(recs)
    pred = unremoved_residuals(spin, scale_factor_pos=s)
    assert dw[2] == pytest.approx(pred['scale_factor'][0][2], rel=1e-3)
    assert pred['scale_factor'][0][2] == pytest.approx(s * spin)
    # alternating direction leaves only the asymmetry
    alt = unremoved_residuals(spin, scale_factor_pos=s, scale_factor_neg=0.001, alternating_direction=True)
    assert alt['scale_factor'][0][2] == pytest.approx(0.5 * (s - 0.001) * spin)
    assert set(pred) == {'axial_bias', 'scale_factor', 'inplane_scale_factor', 'spin_axis_misalignment',
                         'sensor_axis_misalignment', 'total'}


def test_spin_axis_misalignment_leaks_gravity_as_predicted():
    tilt = (0.002, -0.001)
    pred = unremoved_residuals(2 * np.pi, spin_axis_tilt_rad=tilt)['spin_axis_misalignment'][1]
    # the carousel frame is tilted: gravity seen in it is R^T g_body
    f_c = np.array([0, 0, G]) + pred
    chunk, _ = simulate(10.0, 100.0, spin_rate_profile(1.0), body_force=f_c, accel_bias=(0.1, 0.2, 0.0),
                        encoder_hz=100.0)
    _, da = record_errors(_run(chunk))
    np.testing.assert_allclose(da, pred, atol=1e-9)
    assert np.hypot(*pred[:2]) == pytest.approx(G * np.hypot(*tilt), rel=1e-3)


def test_horizontal_axis_mapping_and_inplane_scale_factor():
    m = np.asarray(HORIZONTAL_X_CAROUSEL_TO_BODY)
    np.testing.assert_array_equal(m @ [0, 0, 1], [1, 0, 0])        # spin axis along body x
    assert np.linalg.det(m) == 1
    res = unremoved_residuals(10.0, inplane_scale_factor=(1e-3, 3e-3), carousel_to_body=m)
    np.testing.assert_allclose(res['inplane_scale_factor'][1], [0, 0, 2e-3 * G])   # gravity is in-plane
    np.testing.assert_allclose(res['total'][1], res['inplane_scale_factor'][1] + res['spin_axis_misalignment'][1])
    chunk, _ = simulate(10.0, 100.0, spin_rate_profile(1.0), body_force=m.T @ [0, 0, G], encoder_hz=100.0)
    a = chunk.imu.accel.copy()
    a[:, 0] *= 1 + 1e-3
    a[:, 1] *= 1 + 3e-3
    recs = _run(chunk.with_streams(imu=ImuSamples(chunk.imu.t, chunk.imu.gyro, a)),
                carousel_to_body=HORIZONTAL_X_CAROUSEL_TO_BODY)
    _, da = record_errors(recs)
    np.testing.assert_allclose(da, res['inplane_scale_factor'][1], atol=2e-5)
