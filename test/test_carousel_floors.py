"""carousel/floors.py: the verdicts that tell a miss at the noise floor from a method miss, and the at-rest
information floor (benchmarks/carousel_table3.py prints both)."""
import numpy as np
import pytest

from gyro_thermal_comp.carousel.floors import rest_information_floor, verdict
from gyro_thermal_comp.sim import make_config


def test_verdict_met_floor_and_method():
    seeds = [1, 2, 3]
    assert verdict([60, 80, 55], [90, 120, 70], 50, '>=', seeds) == (True, 'met')
    ok, text = verdict([40, 80, 55], [45, 120, 70], 50, '>=', seeds)        # seed 1: even its floor misses 50x
    assert not ok and text == 'NOT MET: at the floor (no estimator can, floor ratio 45; 1)'
    ok, text = verdict([40, 80, 55], [52, 120, 70], 50, '>=', seeds)        # the floor meets 50x: the method's miss
    assert not ok and text.startswith('NOT MET: method (output/floor 1.30; 1)') and 'at the floor' not in text
    ok, text = verdict([40, 30, 55], [52, 45, 70], 50, '>=', seeds)         # both kinds: the method is named first
    assert text == 'NOT MET: method (output/floor 1.30; 1); at the floor (no estimator can, floor ratio 45; 2)'


def test_verdict_for_errors_compares_the_floor_itself_with_the_target():
    labels = ['1x', '1y']
    assert verdict([1.5, 0.4], [1.0, 1.1], 2.0, '<=', labels) == (True, 'met')
    ok, text = verdict([4.6, 0.4], [1.1, 1.1], 2.0, '<=', labels)           # floor 1.1 <= 2: a method miss
    assert not ok and text == 'NOT MET: method (output/floor 4.18; 1x)'
    ok, text = verdict([4.6, 0.4], [2.5, 1.1], 2.0, '<=', labels)           # floor 2.5 > 2: no estimator can
    assert not ok and text == 'NOT MET: at the floor (no estimator can, floor ratio 2.5; 1x)'


@pytest.fixture(scope='module')
def unit():
    return make_config('carousel_tilted', seed=3, duration_s=600.0, params={'spin_stop_s': 480.0})


def _revolutions(start_s, stop_s, omega):
    period = 2 * np.pi / omega
    ends = np.arange(start_s + period, stop_s, period)
    return [(t, period, omega, int(round(period * 100))) for t in ends]


def test_rest_floor_falls_with_a_longer_still_start_and_never_beats_the_wander_after_the_stop(unit):
    """The still start teaches b0 at zero spin: longer, better. Whatever it and the revolutions tell, the bias
    wanders (Gauss-Markov sigma, tau) from the last revolution to the middle of the rest: a hard lower bound."""
    omega, rest = 3.0, (490.0, 600.0)
    short = rest_information_floor(unit, _revolutions(65.0, 480.0, omega), 60.0, rest)
    long_ = rest_information_floor(unit, _revolutions(185.0, 480.0, omega), 180.0, rest)
    assert np.all(long_ < short)
    sigma = np.radians(unit.unit.gyro_bias_instability_dps[:2])
    last = _revolutions(65.0, 480.0, omega)[-1]
    phi = np.exp(-(0.5 * sum(rest) - (last[0] - 0.5 * last[1])) / unit.params['bias_instability_tau_s'])
    assert np.all(short >= sigma * np.sqrt(1 - phi ** 2))
    assert np.all(short < 3 * sigma)        # and the run does tell b0 (the prior is 1 rad/s)
