"""evaluate(): one pass, fit-before-score, the text table, JSON and the PNG figures."""
import json

import numpy as np
import pytest

from gyro_thermal_comp.evaluation import ORACLE, evaluate
from gyro_thermal_comp.evaluation.plots import save_plots
from gyro_thermal_comp.evaluation.report import chunks_from_list
from gyro_thermal_comp.evaluation.synthetic import DriftIntegrator, level_unit_chunks


class FittedOffset(DriftIntegrator):
    """Two-pass fake: `fit` sees the whole record first (like a global MLR fit)."""

    def __init__(self):
        super().__init__('fitted', 0.0, 0.4)
        self.fit_chunks = 0

    def fit(self, chunks):
        assert self.t_prev is None, 'fit must come before the scoring pass'
        self.fit_chunks = sum(1 for _ in chunks)


class CountingSource:
    def __init__(self, chunks):
        self.chunks, self.calls = chunks, 0

    def __call__(self):
        self.calls += 1
        return iter(self.chunks)


@pytest.fixture(scope='module')
def report():
    chunks = level_unit_chunks(150.0, 50.0, yaw0_rad=0.4, yaw_rate_rad_s=0.02, drift_rad_s=2e-3,
                               noise_rad_s=2e-3, outages=[(80.0, 110.0)], chunk_s=10.0, seed=5)
    source = CountingSource(chunks)
    fitted = FittedOffset()
    rep = evaluate(source, [DriftIntegrator('biased', 1e-4, 0.4), fitted])
    assert source.calls == 2 and fitted.fit_chunks == len(chunks)
    assert rep.imu_samples == sum(c.imu.t.size for c in chunks)
    return rep


def test_text_table(report):
    text = report.to_text()
    lines = text.splitlines()
    header = next(line for line in lines if line.startswith('method'))
    for col in ('max|e| deg', 'mean deg', 'var deg^2', 'RMS deg', 'out max|e|', 'out exc max',
                'bias mean deg/s', 'bias var (deg/s)^2'):
        assert col in header
    rows = [line for line in lines if line.split()[:1] in (['biased'], ['fitted'], [ORACLE])]
    assert len(rows) >= 3 and len({len(r) for r in rows[:3]}) == 1  # fixed width
    biased = next(r for r in rows if r.startswith('biased')).split()
    assert float(biased[7]) == pytest.approx(np.degrees(1e-4), rel=1e-3)  # bias error mean, deg/s
    assert 'outage spans' in text and 'speed, IMU samples/s' in text


def test_json_is_strict_and_in_degrees(report):
    d = json.loads(report.to_json(include_series=True))  # strict: NaN must have become null
    m = d['methods']['biased']
    assert m['bias_error_mean_deg_s'] == pytest.approx(np.degrees(1e-4), rel=1e-6)
    assert m['bias_error_var_deg2_s2'] == pytest.approx(0.0, abs=1e-20)
    assert d['methods'][ORACLE]['bias_error_mean_deg_s'] is None
    assert len(d['spans']) == 1 and d['spans'][0]['duration_s'] == pytest.approx(30.0 - 0.02)
    growth = d['spans'][0]['methods']['biased']['excess_growth_deg']
    assert growth == pytest.approx(-np.degrees(1e-4) * (30.0 - 0.02), rel=1e-6)
    # a constant drift error: freezing the estimate at the span start changes nothing
    frozen = d['spans'][0]['methods']['biased']['frozen_excess_growth_deg']
    assert frozen == pytest.approx(growth, rel=1e-3)
    assert d['spans'][0]['floor_deg'] is None            # no temperature stream: no floor
    assert len(d['series_1s']['t_s']) == len(d['series_1s']['e_deg:biased']) == 150
    assert d['allan_rate_error']['biased']['tau_s'][0] == 1.0
    json.loads(report.to_json())


def test_plots_are_written(report, tmp_path):
    paths = save_plots(report, tmp_path, prefix='x_')
    assert [p.name for p in paths] == ['x_heading_error.png', 'x_drift.png', 'x_allan.png']
    for p in paths:
        assert p.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and p.stat().st_size > 10_000


def test_evaluate_runs_the_peers_side_by_side():
    from gyro_thermal_comp.evaluation import default_peers
    pytest.importorskip('imufusion')
    pytest.importorskip('ahrs')
    chunks = level_unit_chunks(75.0, 40.0, yaw0_rad=-3.0, drift_rad_s=2e-3, noise_rad_s=1e-3,
                               outages=[(65.0, 75.0)], mag_rate_hz=20.0, chunk_s=10.0)
    rep = evaluate(chunks_from_list(chunks), default_peers())
    series = rep.result.series
    before = series.centers_s() - rep.result.t_start_s < 64.0
    for name in ('fusion', 'mahony'):
        row = rep.rows()[name]
        assert np.abs(np.degrees(series.error(name)[before])).max() < 1.0
        assert row['outage_max_abs_deg'] > 5.0  # both end up following the disturbed field
        assert np.isfinite(row['bias_error_mean_deg_s'])
        assert rep.samples_per_s(name) > 0
    assert rep.rows()['fusion']['coasting_fraction_in_outage'] > 0.4  # 5 s of 10 s rejected
