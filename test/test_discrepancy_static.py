"""Acceptance on a motionless unit (reference 'static'): hidden thermal effects on the simulator's
`null` scenario (drift exactly a*T + b*dT/dt + c otherwise), the null answer, and a disturbance
outside the library. Bags are short-rate (2 Hz IMU) 2 h simulations made here; the workflow only
ever sees the bag (or its sensor chunks) - never the effect's name or the simulator's truth."""
import json

import numpy as np
import pytest

from gyro_thermal_comp.bag_io import BagWriter
from gyro_thermal_comp.cli import write_simulation
from gyro_thermal_comp.discrepancy import discover
from gyro_thermal_comp.samples import ImuSamples
from gyro_thermal_comp.sim import make_config, simulate

RATES = dict(imu_rate_hz=2.0, mag_rate_hz=2.0, temp_rate_hz=1.0)
SHRINK = 0.3


def _null(seed, **effects):
    return make_config('null', seed=seed, effects=effects, **RATES)


def _sensor_only(cfg):
    """The sensor streams of a simulation (what a real bag has)."""
    for c in simulate(cfg):
        yield c.with_streams(gyro_bias=None, mag_disturbance=None, odom=None)


@pytest.mark.parametrize('seed', [11, 12])
def test_null_chunks_no_missing_effect(seed):
    r = discover(_sensor_only(_null(seed)), reference='static')
    assert r.verdict == 'no_missing_effect' and r.effects == [] and r.effect is None


def test_null_bag_with_report(tmp_path):
    bag = tmp_path / 'null_bag'
    write_simulation(_null(13), bag)
    r = discover(bag, reference='static', report_dir=tmp_path / 'report')
    assert r.verdict == 'no_missing_effect'
    d = json.loads((tmp_path / 'report' / 'discovery.json').read_text())
    for key in ('verdict', 'effect', 'effects', 'candidates', 'residual_rms_before', 'residual_rms_after',
                'heading_error_rms_before', 'heading_error_rms_after'):
        assert key in d
    assert d['effect'] is None and d['effects'] == []
    assert set(d['candidates']) >= {'thermal_curvature', 'thermal_hysteresis', 'thermal_lag', 'g_sensitivity',
                                    'scale_factor', 'scale_factor_thermal', 'cross_axis', 'time_offset',
                                    'compass_deviation', 'rate_random_walk', 'bias_instability'}
    assert d['candidates']['scale_factor'] is None          # not testable on a static unit
    for name in ('summary.md', 'residual_vs_time.png', 'residual_vs_regime.png', 'candidate_scores.png',
                 'heading_error.png'):
        assert (tmp_path / 'report' / name).stat().st_size > 0
    assert 'no missing effect' in (tmp_path / 'report' / 'summary.md').read_text()


@pytest.mark.parametrize('effect, value', [('thermal_curvature', 6e-5), ('thermal_lag', 200.0),
                                           ('thermal_hysteresis', 0.03)])
def test_hidden_thermal_effect_is_named_and_gap_shrinks(effect, value):
    r = discover(_sensor_only(_null(21, **{effect: value})), reference='static')
    d = r.to_dict()
    assert r.verdict == 'effect_found' and r.effect == effect, d['candidates']
    assert d['residual_rms_after'] <= SHRINK * d['residual_rms_before']
    assert d['heading_error_rms_after'] < d['heading_error_rms_before']
    assert d['candidates'][effect] == max(v for v in d['candidates'].values() if v is not None) or \
        d['iterations'][0]['encompassing_checks']                # the choice is explained


def test_two_interacting_effects_larger_first():
    """A curvature seen through a lagged die temperature: neither alone predicts held-out blocks (each
    misfits the other's part), together they do - the random walk must not take the gap."""
    r = discover(_sensor_only(_null(31, thermal_curvature=1.2e-4, thermal_lag=240.0)), reference='static')
    assert r.effects[:2] == ['thermal_curvature', 'thermal_lag']


def test_gauss_markov_bias_is_named_with_its_correlation_time():
    """A bias wandering around its mean (tau 60 s, sigma 0.02 deg/s on z): told from a random walk
    by its mean reversion; tau is estimated (30 s coarse bins round it up a little)."""
    cfg = make_config('null', seed=42, effects={'bias_instability': 0.02}, params={'bias_instability_tau_s': 60.0},
                      **RATES)
    r = discover(_sensor_only(cfg), reference='static')
    assert r.effects == ['bias_instability'], r.candidates
    s = r.input_settings()
    assert 40.0 < s['bias_instability_tau_s'][2] < 150.0 and 0.012 < s['bias_instability_dps'][2] < 0.03


def test_disturbance_outside_library_is_unexplained(tmp_path):
    """A periodic 0.01 deg/s, 400 s disturbance added to the gyro (no candidate has that shape)."""
    bag = tmp_path / 'periodic'
    amp = np.radians(0.01)
    with BagWriter(bag) as w:
        for c in simulate(_null(41)):
            g = c.imu.gyro.copy()
            g[:, 2] += amp * np.sin(2 * np.pi * c.imu.t / 400.0)
            g[:, 0] += amp * np.cos(2 * np.pi * c.imu.t / 400.0)
            w.write_chunk(c.with_streams(imu=ImuSamples(c.imu.t, g, c.imu.accel), gyro_bias=None,
                                         mag_disturbance=None, odom=None))
    r = discover(bag, reference='static')
    assert r.verdict == 'unexplained_residual' and r.effects == []
    assert r.whiteness_after['structured']
