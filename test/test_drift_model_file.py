"""The drift model file: what `discover` names becomes terms the estimator runs,
the causal inputs those terms need, and the coasting prediction that knows what it has not seen."""
import math
import subprocess
import sys

import numpy as np
import pytest

from gyro_thermal_comp.thermal.coasting import DriftPrediction, InputCoverage
from gyro_thermal_comp.thermal.drift_model import DriftModel
from gyro_thermal_comp.thermal.estimator import EstimatorConfig, ThermalDriftEstimator
from gyro_thermal_comp.thermal.model_file import DriftModelFile, TermSetting
from gyro_thermal_comp.thermal.model_inputs import ModelInputs

from conftest import BAGS, REPO

BRANCH_FILE = DriftModelFile(
    terms=(TermSetting('constant'), TermSetting('temperature', prior=1e-4, prior_sigma=5e-5),
           TermSetting('temperature_rate'), TermSetting('thermal_branch', q_sigma=0.0)),
    lag_tau_s=60.0, branch=(900.0, 0.002), coverage={'temperature_c': (23.0, 58.0), 'temperature_rate_c_s': (-0.01, 0.02)},
    source={'bag': 'test'})


def test_a_model_file_round_trips_through_yaml(tmp_path):
    path = BRANCH_FILE.save(tmp_path / 'model.yaml')
    back = DriftModelFile.load(path)
    assert back == BRANCH_FILE
    cfg = EstimatorConfig(drift_model_file=back)
    assert cfg.model().names == ('constant', 'temperature', 'temperature_rate', 'thermal_branch')
    # the file's sigmas where it gives them, the terms' own elsewhere
    generic = DriftModel(('constant', 'temperature_rate')).prior_sigmas()
    np.testing.assert_allclose(cfg.prior_sigma_values(cfg.model()), [generic[0], 5e-5, generic[1], 1e-3], rtol=0)
    assert cfg.q_matrix(cfg.model())[3, 3] == 0.0


@pytest.mark.parametrize('text, expected', [
    ('format: other\nterms: []\n', 'format must be'),
    ('format: gyro_thermal_comp/drift_model/1\nterms:\n- {name: specific_force_x}\n', 'cannot run in the estimator'),
    ('format: gyro_thermal_comp/drift_model/1\nterms:\n- {name: constant}\n- {name: thermal_branch}\n',
     'thermal_branch needs'),
    ('format: gyro_thermal_comp/drift_model/1\nterms:\n- {name: constant, prior_sigma: -1}\n', 'prior_sigma must be > 0'),
    ('format: gyro_thermal_comp/drift_model/1\nterms:\n- {name: constant}\ninputs: {thermal_lag_tau_s: .nan}\n',
     'must be a finite number'),
    ('terms: [unclosed\n', 'not YAML'),
])
def test_a_bad_model_file_is_one_line_naming_the_file(tmp_path, text, expected):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        DriftModelFile.load(path)
    assert expected in str(err.value) and str(path) in str(err.value) and '\n' not in str(err.value)


def test_discover_writes_a_model_the_estimator_runs(tmp_path):
    """discover -> file -> estimator terms, through the CLI as a user runs it; a bad --model path is
    one line and a non-zero exit."""
    model = tmp_path / 'unit.yaml'
    cli = [sys.executable, '-m', 'gyro_thermal_comp.cli']
    run = subprocess.run([*cli, 'discover', str(BAGS / 'static_ramp'), '--write-model', str(model)],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert run.returncode == 0, run.stderr
    f = DriftModelFile.load(model)
    assert f.source['effects'] and f.source['verdict'] == 'effect_found'
    est = ThermalDriftEstimator(EstimatorConfig(drift_model_file=f))
    assert est.model.names == f.names
    bad = subprocess.run([*cli, 'replay', str(BAGS / 'static_ramp'), '--out', str(tmp_path / 'o'), '--model',
                          str(tmp_path / 'missing.yaml')], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert bad.returncode != 0 and 'drift_model_file' in bad.stderr and 'Traceback' not in bad.stderr


def test_die_lag_and_branch_are_causal_and_chunk_independent():
    t = np.arange(0.0, 4000.0, 0.05)
    temp = 25.0 + 10.0 * np.clip((t - 500.0) / 1500.0, 0.0, 1.0) - 8.0 * np.clip((t - 2500.0) / 1000.0, 0.0, 1.0)
    rate = np.gradient(temp, t)
    known = np.ones(t.size, bool)
    whole = ModelInputs(60.0, 900.0, 0.002).at(t, temp, rate, known, np.zeros(t.size))
    pieces = ModelInputs(60.0, 900.0, 0.002)
    parts = [pieces.at(t[i:i + 997], temp[i:i + 997], rate[i:i + 997], known[i:i + 997], np.zeros(min(997, t.size - i)))
             for i in range(0, t.size, 997)]
    for name in whole:
        np.testing.assert_allclose(np.concatenate([p[name] for p in parts]), whole[name], rtol=0, atol=1e-9)
    die, die_rate, m = whole['temperature'], whole['temperature_rate'], whole['thermal_branch']
    # on the heating ramp (6.7e-3 degC/s) the die lags by rate x tau = 0.4 degC and its rate catches up
    k = np.searchsorted(t, 1900.0)
    assert die[k] == pytest.approx(temp[k] - rate[k] * 60.0, abs=0.02)
    assert die_rate[k] == pytest.approx(rate[k], rel=0.02)
    # the branch is + after heating, - after cooling, and relaxes at the hold in between
    assert m[np.searchsorted(t, 2000.0)] > 0.7
    assert m[np.searchsorted(t, 2499.0)] < m[np.searchsorted(t, 2000.0)]
    assert m[np.searchsorted(t, 3499.0)] < -0.4   # 1000 s of cooling, tau 900 s: -1 + 1.6 exp(-1.1) = -0.47


def test_coasting_keeps_the_model_where_the_windows_covered_and_falls_back_beyond():
    model = DriftModel(('constant', 'temperature', 'temperature_rate'))
    x = np.array([0.0, 1e-4, 2e-2])
    P = np.diag([1e-8, 1e-14, 1e-10])
    cov = InputCoverage({'temperature_c': (20.0, 40.0), 'temperature_rate_c_s': (0.0, 0.02)})
    pred = DriftPrediction(model, cov)
    pred.rebase(model.rows(model.neutral_inputs(30.0, 0.0))[0], 0.0)     # at a hold, as at the hold -> cooling turn
    d_u = float(model.rows(model.neutral_inputs(30.0, 0.0))[0] @ x)

    def run(temp, rate):
        inputs = model.neutral_inputs(np.array([temp]), rate)
        d, kappa = pred.predict(model.rows(inputs), inputs, x, P, np.array([60.0]))
        pred.refresh(inputs, x, P, 60.0)
        return d, kappa, np.array([pred.var_extra])

    d, kappa, var = run(35.0, 0.015)              # inside what was covered: the model's change
    assert kappa[0] > 0.99 and d[0] == pytest.approx(float(model.evaluate(x, model.neutral_inputs(35.0, 0.015))[0]),
                                                     rel=1e-3)
    d, kappa, var = run(30.0, -0.01)              # cooling, never seen: back to the held drift
    full = float(model.evaluate(x, model.neutral_inputs(30.0, -0.01))[0])
    assert kappa[0] == 0.0 and d[0] == pytest.approx(d_u, abs=1e-15) and full < d_u
    assert var[0] == pytest.approx((full - d_u) ** 2, rel=1e-9)   # the change it did not follow, in its variance
    _, _, var_far = run(30.0, -0.02)
    assert var_far[0] > var[0] > 0.0             # more the further out
    d_hot, k_hot, var_hot = run(50.0, 0.01)      # past the covered temperature: the slope carries on in part
    hot = float(model.evaluate(x, model.neutral_inputs(50.0, 0.01))[0])
    assert 0.5 < k_hot[0] < 1.0 and d_u < d_hot[0] < hot and var_hot[0] > 0.0


def test_coasting_beyond_the_covered_inputs_says_so_in_its_variance():
    """Inside the temperatures and dT/dt the accepted windows covered, the prediction adds no
    extrapolation variance; past them it adds some, more the further out, for the temperature and
    for dT/dt each (the parameters' own uncertainty, P, kept out of it: P = 0): as the error of the
    part it follows and the change it does not."""
    model = DriftModel(('constant', 'temperature', 'temperature_rate'))
    x = np.array([0.0, 1e-4, 2e-2])
    cov = InputCoverage({'temperature_c': (20.0, 40.0), 'temperature_rate_c_s': (0.0, 0.02)})
    pred = DriftPrediction(model, cov)
    pred.rebase(model.rows(model.neutral_inputs(30.0, 0.01))[0], 0.0)

    def beyond(temp, rate):
        inputs = model.neutral_inputs(np.array([temp]), rate)
        pred.refresh(inputs, x, np.zeros((3, 3)), 60.0)
        return pred.var_beyond + pred.var_unfollowed

    assert beyond(35.0, 0.01) == 0.0 and beyond(20.0, 0.0) == 0.0
    assert 0.0 < beyond(45.0, 0.01) < beyond(50.0, 0.01) < beyond(60.0, 0.01)        # hotter than covered
    assert 0.0 < beyond(30.0, -0.005) < beyond(30.0, -0.01) < beyond(30.0, -0.02)    # cooling, never seen


def test_nothing_covered_means_nothing_trusted():
    cov = InputCoverage()
    t_c, r_c, rel_t, rel_r = cov.clamp(np.array([30.0]), np.array([0.01]))
    assert rel_t[0] == 1.0 and rel_r[0] == 1.0
    cov.add(0.0, 25.0, 30.0, 0.0, 0.01)
    cov.add(10.0, math.nan, 1.0, 0.0, 0.0)        # a window with nothing known adds nothing
    assert cov.to_dict() == {'temperature_c': [25.0, 30.0], 'temperature_rate_c_s': [0.0, 0.01]}


def test_coverage_is_what_the_learner_still_remembers():
    """A fading-memory learner has forgotten windows older than its memory: so has the envelope."""
    cov = InputCoverage({'temperature_c': (10.0, 12.0), 'temperature_rate_c_s': (-0.001, 0.0)}, memory_s=1000.0)
    cov.add(100.0, 20.0, 21.0, 0.0, 0.001)
    assert cov.temp == (10.0, 21.0)               # a file's ranges count as seen at the start
    cov.add(900.0, 22.0, 23.0, 0.0, 0.002)
    assert cov.temp == (10.0, 23.0) and cov.rate == (-0.001, 0.002)
    cov.add(1500.0, 24.0, 24.5, 0.0, 0.0)           # those of t = 100 s are forgotten
    assert cov.temp == (22.0, 24.5) and cov.rate == (0.0, 0.002)


def _static_ramp(effect: str, size: float):
    """The package simulator's oven run at 5 Hz with one effect beyond the paper's model."""
    from gyro_thermal_comp import sim
    from gyro_thermal_comp.sim.effects import EFFECTS
    effects = {name: 0.0 for name in EFFECTS}
    effects[effect] = size
    return sim.make_config('static_ramp', seed=5, effects=effects, imu_rate_hz=5, truth_rate_hz=5, mag_rate_hz=5,
                           temp_rate_hz=1)


def _run(cfg, model_file=None):
    from gyro_thermal_comp import sim
    est = ThermalDriftEstimator(EstimatorConfig(drift_model_file=model_file))
    err = []
    for chunk in sim.simulate(cfg):
        out = est.process(chunk)
        truth = np.interp(chunk.imu.t, chunk.gyro_bias.t, chunk.gyro_bias.vec[:, 2])
        err.append(out.track.drift_rad_s - truth)
    err = np.concatenate(err)
    return est, float(np.sqrt(np.nanmean(err[err.size // 4:] ** 2)))


def test_the_stkf_learns_a_hysteresis_coefficient_online():
    """A model file with the heating/cooling branch (its settings as the simulator's, no starting
    value): over one oven run the STKF learns h from zero to within 3 sigma of the truth, with a sigma
    under a third of |h| (learned from the data, not the 0.06 deg/s prior)."""
    cfg = _static_ramp('thermal_hysteresis', 0.02)
    branch = DriftModelFile(terms=tuple(TermSetting(n) for n in ('constant', 'temperature', 'temperature_rate',
                                                                 'thermal_branch')), branch=(900.0, 0.002))
    est, _ = _run(cfg, branch)
    h, sigma = est.params[3], math.sqrt(est.learner.P[3, 3])
    truth = math.radians(cfg.unit.to_dict()['gyro_hysteresis_dps'][2])
    assert abs(h - truth) <= 3.0 * sigma and sigma < abs(truth) / 3.0


def test_a_die_lag_in_the_model_follows_a_lagging_die():
    """A die lagging the temperature sensor by 300 s: with the lag in the model file the drift estimate
    is closer to the truth (RMS over the last three quarters of the run) than the default model's."""
    cfg = _static_ramp('thermal_lag', 300.0)
    lag = DriftModelFile(terms=tuple(TermSetting(n) for n in ('constant', 'temperature', 'temperature_rate')),
                         lag_tau_s=300.0)
    _, rms_default = _run(cfg)
    _, rms_lag = _run(cfg, lag)
    assert rms_lag < 0.7 * rms_default


def test_a_state_with_a_bad_coverage_is_refused_before_anything_changes():
    est = ThermalDriftEstimator(EstimatorConfig(terms=('constant', 'temperature', 'temperature_rate')))
    good = {'terms': ['constant', 'temperature', 'temperature_rate'], 'temperature_ref_c': 25.0, 'x': [0.0, 1e-4, 1e-2]}
    for bad in ({'temperature_c': [30.0, 20.0]}, {'temperature_c': 'hot'}, {'temperature_rate_c_s': [0, math.inf]}, [1, 2]):
        with pytest.raises(ValueError):
            est.set_state({**good, 'coverage': bad})
        assert est.get_state().get('coverage') is None and est.param_state.warm is None
    est.set_state({**good, 'coverage': {'temperature_c': [20.0, 30.0], 'temperature_rate_c_s': [0.0, 0.01]}})
    assert est.get_state()['coverage'] == {'temperature_c': [20.0, 30.0], 'temperature_rate_c_s': [0.0, 0.01]}


def test_a_state_file_is_matched_to_the_model_file_by_term_name(ros, tmp_path):
    """A model file written again (discover run anew, edited by hand) may list the same terms in
    another order: the node's learned state still belongs to it, term by term."""
    from gyro_thermal_comp.nodes.compose import make_stkf_node
    from gyro_thermal_comp.nodes.state_store import StateStore
    terms = ('constant', 'temperature', 'temperature_rate')
    learned = {'constant': -2.1e-3, 'temperature': 1.2e-4, 'temperature_rate': 4e-3}
    sigmas = {'constant': 1e-4, 'temperature': 2e-5, 'temperature_rate': 3e-3}
    state = {'terms': list(terms), 'temperature_ref_c': 25.0, 'x': [learned[n] for n in terms],
             'P': np.diag([sigmas[n] ** 2 for n in terms]).tolist()}
    with StateStore(tmp_path / 'state.json') as store:
        store.save(state)
    model = DriftModelFile(terms=tuple(TermSetting(n) for n in reversed(terms))).save(tmp_path / 'model.yaml')
    node = make_stkf_node({'state_file': str(tmp_path / 'state.json'), 'drift_model_file': str(model)})
    try:
        assert node.state_status.startswith('warm start'), node.state_status
        est = node.estimator
        assert est.model.names == tuple(reversed(terms))
        assert dict(zip(est.model.names, est.params.tolist())) == learned
        P = np.asarray(est.get_state()['P'])
        assert dict(zip(est.model.names, np.sqrt(np.diag(P)).tolist())) == pytest.approx(sigmas, rel=1e-12)
    finally:
        node.destroy_node()
    assert not list(tmp_path.glob('state.json.rejected-*'))
