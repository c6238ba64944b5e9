"""A record the estimator cannot learn from says so: one log line, a named /diagnostics reason, a
line in `replay` and `evaluate` output; the status never says "learning" when nothing is learned.

The checks are general: a record either learns (filter updates) or names why it does not, with a
reason its output rows show. A 1 Hz record with the defaults did not learn (every sample a time
gap); a record without a compass, or with its field disturbed from the still period to the end,
cannot learn whatever the rates."""
import re
from dataclasses import replace

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from conftest import Capture
from gyro_thermal_comp.cli import evaluate_bag, write_simulation
from gyro_thermal_comp.evaluation.report import chunks_from_list, evaluate
from gyro_thermal_comp.evaluation.synthetic import level_unit_chunks
from gyro_thermal_comp.learning_status import LearningStatus
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.thermal import EstimatorConfig, ThermalDriftEstimator
from gyro_thermal_comp.thermal.reasons import REASON_BIT

REASON = re.compile(r'^not learning: (every window crosses a time gap|\d+ % of the windows cross a time gap|'
                    r'gate shut by \w+ for \d+ % of|[a-z ]+ for \d+ % of|the innovation test refused|'
                    r'no window had a usable)')


def _says(line: str) -> bool:
    """True if the line says the filter learned (updates > 0); else it must name why not."""
    if line.startswith('learning: '):
        assert int(re.match(r'learning: (\d+) filter updates', line).group(1)) > 0, line
        return True
    assert REASON.match(line), line
    return False


@pytest.fixture(scope='module')
def one_hz_bag(tmp_path_factory):
    """20 min of the static ramp, every stream at 1 Hz (a tag or logger point-sampled to 1 Hz)."""
    from gyro_thermal_comp import sim
    path = tmp_path_factory.mktemp('one_hz') / 'ramp_1hz'
    write_simulation(sim.make_config('static_ramp', seed=5, duration_s=1200.0, imu_rate_hz=1.0, mag_rate_hz=1.0,
                                     temp_rate_hz=1.0, truth_rate_hz=1.0), path)
    return path


def test_a_1_hz_record_learns_or_says_why_not_in_replay_and_evaluate(ros, one_hz_bag, tmp_path):
    from gyro_thermal_comp.evaluation.carousel_outputs import diagnostics_from_bag
    from gyro_thermal_comp.nodes.replay import replay
    summary = []
    replay(one_hz_bag, tmp_path / 'out', summary=summary)
    [line] = summary
    assert line.startswith('stkf_node: ')
    learned = _says(line.removeprefix('stkf_node: '))
    print(line)
    reports = diagnostics_from_bag(tmp_path / 'out')
    assert len(reports) > 1000
    for _, level, message, values in reports:   # never "learning" without an update
        if message.startswith('learning'):
            assert int(values['filter_updates']) > 0, message
    _, level, message, values = reports[-1]
    if not learned:
        assert int(values['filter_updates']) == 0
        assert level == DiagnosticStatus.WARN[0] and line.removeprefix('stkf_node: ') in message
    report = evaluate_bag(one_hz_bag, peers=False)
    assert _says(report.learning['stkf']) == learned
    if not learned:
        assert f"stkf: {report.learning['stkf']}" in report.to_text().splitlines()


class _Log:
    def __init__(self):
        self.warnings = []

    def warning(self, text, **_):
        self.warnings.append(text)

    def info(self, text, **_):
        pass

    error = debug = info


def test_a_record_without_a_compass_says_so_once(ros):
    chunks = [replace(c, mag=None) for c in level_unit_chunks(400.0, 50.0, drift_rad_s=0.002, noise_rad_s=0.001)]
    node = make_stkf_node()
    node.pubs = {name: Capture() for name in node.pubs}
    node.get_logger = lambda log=_Log(): log
    reports = []
    for chunk in chunks:
        node.process_chunk(replace(chunk, odom=None, gyro_bias=None, mag_disturbance=None))
        reports.append(node.diagnostic_values())
    said = [w for w in node.get_logger().warnings if 'not learning' in w]
    node.destroy_node()
    level, message, values = reports[-1]
    assert values['filter_updates'] == 0 and level == DiagnosticStatus.WARN
    assert 'not learning: no compass for 100 % of the record' in message
    assert said == ['not learning: no compass for 100 % of the record']
    assert not any(m.startswith('learning') for _, m, _ in reports)


def test_a_field_disturbed_from_the_still_period_on_says_so_in_evaluate():
    chunks = level_unit_chunks(900.0, 50.0, drift_rad_s=0.002, noise_rad_s=0.001, outages=[(20.0, 900.0)])
    report = evaluate(chunks_from_list(chunks), [ThermalDriftEstimator(EstimatorConfig())], outage_truth=False)
    line = report.learning['stkf']
    assert not _says(line) and 'gate shut by field_norm for 100 % of the record' in line
    assert f'stkf: {line}' in report.to_text().splitlines()
    assert report.to_dict()['learning'] == {'stkf': line}


def test_the_reasons_are_counted_per_window():
    gap, norm = REASON_BIT['time_gap'], REASON_BIT['field_norm']
    t = np.arange(0.0, 200.0, 0.1)
    status = LearningStatus(10.0)
    reasons = np.where(np.arange(t.size) % 150 == 0, gap, 0)       # one gap every 15 s: in 13 of 19 windows
    reasons = reasons | np.where(t < 60.0, norm, 0)                 # the gate shut for the first 30 %
    status.add(t, reasons, np.ones(t.size, bool), 0)
    assert status.verdict({}, min_windows=25) is None              # too early to say
    line = status.verdict({})
    assert line == 'not learning: 68 % of the windows cross a time gap (IMU stamps further apart than max_gap_s)'
    assert status.verdict({'filter_updates': 3}) is None            # it learned
    status.add(t + 200.0, np.full(t.size, REASON_BIT['turn_rate']), np.ones(t.size, bool), 3)
    assert status.verdict({'filter_updates': 3}, since_update=True, by_design=('turn_rate',)) is None
    assert status.verdict({'filter_updates': 3}, since_update=True) == \
        'not learning: gate shut by turn_rate for 100 % of the last 3 min'
    assert status.verdict({}, learn=False) == 'not learning: learning is off (learn: false)'
