"""Issue 3 targets on the bundled bags (acceptance 2). Every method runs over each bag in one pass,
as `gyro-thermal-comp evaluate` does. How the thresholds scale from the full-rate targets is in
docs/evaluation.md ("Targets on the bundled bags"); full-length, 10-seed figures come from
benchmarks/stkf_targets.py.

Targets the estimator does not meet are `xfail(strict=True)`: they fail loudly here the day they
start to hold, and the reason each one misses is written beside it."""
from pathlib import Path

import numpy as np
import pytest

from gyro_thermal_comp.cli import evaluate_bag

BAGS = Path(__file__).resolve().parents[1] / 'bags'
ARW_DEG_SQRT_S = 0.04
COMPASS_RATE_SCALE = (50.0 / 5.0) ** 0.25   # full-rate compass 50 Hz, bundled 5 Hz (docs/evaluation.md)
THERMAL = ('stkf', 'kf', 'mlr_whole_record', 'lsm')   # mlr: no calibration bag here


@pytest.fixture(scope='module')
def reports():
    return {name: evaluate_bag(BAGS / name).to_dict(include_series=True) for name in
            ('static_ramp', 'static_ramp_outages', 'vehicle_loop')}


def _max_e(d, name):
    return d['methods'][name]['max_abs_deg']


def _scored(d):
    """Every scored method, stkf and oracle aside; only `mlr` may be left out (not applicable without a
    calibration bag)."""
    skipped = [n for n, m in d['methods'].items() if m.get('status') == 'not_applicable']
    assert skipped == ['mlr'], skipped
    return [n for n in d['methods'] if n not in ('stkf', 'oracle', *skipped)]


def test_static_ramp_heading_and_bias(reports):
    d = reports['static_ramp']
    assert _max_e(d, 'stkf') <= 0.3 * COMPASS_RATE_SCALE
    # the paper's 2e-5 deg/s is below the white-noise floor of the record (ARW / sqrt(duration));
    # the STKF stays within twice that floor
    floor = ARW_DEG_SQRT_S / np.sqrt(d['duration_s'])
    assert abs(d['methods']['stkf']['bias_error_mean_deg_s']) <= 2.0 * floor


def test_static_ramp_stkf_ties_the_best(reports):
    """With the compass correcting every method, the compass sets the static error: the STKF is
    the best or within 0.02 deg of it (a tie at the compass-noise resolution)."""
    d = reports['static_ramp']
    others = [_max_e(d, n) for n in _scored(d)]
    assert _max_e(d, 'stkf') <= min(others) + 0.02


@pytest.mark.parametrize('bag', ['static_ramp_outages', 'vehicle_loop'])
def test_stkf_has_the_lowest_max_heading_error(reports, bag):
    d = reports[bag]
    for name in _scored(d):
        assert _max_e(d, 'stkf') < _max_e(d, name), name


def test_outages_coasting_beats_a_frozen_bias(reports):
    """Coasting on the model: on the heating ramp and the cooling tail the STKF's excess growth is
    at most a third of what its own estimate frozen at the outage start would give, and within 3
    information-floor sigmas (the best unbiased prediction from the windows before)."""
    spans = reports['static_ramp_outages']['spans']
    assert len(spans) == 3
    for k in (0, 2):
        s = spans[k]['methods']['stkf']
        assert abs(s['excess_growth_deg']) <= abs(s['frozen_excess_growth_deg']) / 3.0, k
        assert abs(s['excess_growth_deg']) <= 3.0 * spans[k]['floor_deg'], k


@pytest.mark.xfail(strict=True, reason='issue 3 target 2 (0.5 deg / 300 s, 1.0 deg / 600 s, 0.1 x frozen): '
                   'below the information floor at the heating-ramp outage (1.8 deg 1-sigma on this bag) and '
                   'the model cannot predict the start of cooling from heating data (die lag and hysteresis)')
def test_outage_target_of_the_issue(reports):
    for span in reports['static_ramp_outages']['spans']:
        s = span['methods']['stkf']
        limit = 0.5 if span['duration_s'] < 450 else 1.0
        assert abs(s['excess_growth_deg']) <= min(limit, 0.1 * abs(s['frozen_excess_growth_deg']))


@pytest.mark.xfail(strict=True, reason='issue 3 target 2: max|e| < 1.8 deg on static_ramp_outages; the '
                   'hold-to-cooling outage alone costs more (see test_outage_target_of_the_issue)')
def test_outage_bag_max_heading_error(reports):
    assert _max_e(reports['static_ramp_outages'], 'stkf') < 1.8


@pytest.mark.xfail(strict=True, reason='issue 3 target 3 (2 deg): the first lap costs the unlearned gyro '
                   'scale factor x the turns (1 % x 360 deg = 3.6 deg) before a closed lap makes it observable')
def test_vehicle_loop_max_heading_error(reports):
    assert _max_e(reports['vehicle_loop'], 'stkf') <= 2.0


def test_vehicle_loop_after_the_first_lap(reports):
    """Once a lap has closed (scale factor and compass deviation observable) the error stays within
    the issue's 2 deg: the worst 1 s mean from 400 s on (laps take 152 s after 60 s still)."""
    series = reports['vehicle_loop']['series_1s']
    t, e = np.array(series['t_s']), np.array(series['e_deg:stkf'], dtype=float)
    assert np.nanmax(np.abs(e[t >= 400.0])) <= 2.0


@pytest.mark.xfail(strict=True, reason='issue 3 target 4, MLR worst on static_ramp: with the compass '
                   'correcting every method the static error is the compass\'s (all within 0.2 deg); the '
                   'paper\'s MLR figure is gyro dead reckoning')
def test_mlr_is_the_worst_thermal_method_on_static_ramp(reports):
    d = reports['static_ramp']
    assert _max_e(d, 'mlr_whole_record') >= max(_max_e(d, n) for n in THERMAL)
