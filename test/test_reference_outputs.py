"""The core's outputs on every bundled bag are those committed in test/reference/ (written by
`test/reference_outputs.py --write BAG...`), to the cross-CPU tolerance of bag_compare. A deliberate
behaviour change rewrites the bags it moves in the same commit, with the deltas it printed."""
import numpy as np
import pytest

from reference_outputs import (CAROUSEL_BAGS, PROVENANCE, THERMAL_BAGS, compute, deltas, describe,
                               differences, main, read)


@pytest.mark.parametrize('name', THERMAL_BAGS + CAROUSEL_BAGS)
def test_outputs_match_the_committed_reference(name):
    ref, prov = read(name)
    problems = differences(compute(name), ref, name)
    assert not problems, '\n'.join(problems + [
        f'reference {describe(prov)}; after a deliberate change: .venv/bin/python test/reference_outputs.py '
        f'--write {name}'])


@pytest.mark.parametrize('name', THERMAL_BAGS + CAROUSEL_BAGS)
def test_each_reference_says_who_wrote_it(name):
    _, prov = read(name)
    assert len(prov['commit']) == 40 and prov['command'].startswith('test/reference_outputs.py --write ')
    assert name in prov['command'].split()
    assert {'gyro_thermal_comp', 'numpy', 'scipy'} <= set(prov['versions'])


def test_the_node_outputs_and_the_calibrated_methods_are_in_the_references():
    ref, _ = read('static_ramp_outages')
    for key in ('node.heading_rad', 'node.heading_var_rad2', 'node.gyro_compensated_rad_s', 'node.yaw_var_rad2',
                'stkf_model.heading_rad', 'stkf_model.state.x', 'mlr.heading_rad', 'calibration.mlr.x',
                'calibration.model.priors'):
        assert key in ref and np.size(ref[key]) > 0, key
    assert 'mlr.heading_rad' not in read('vehicle_loop')[0]


def test_writing_needs_the_bags_named(capsys):
    with pytest.raises(SystemExit) as exc:
        main(['--write'])
    assert exc.value.code == 2 and 'needs the bags it rewrites' in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(['--write', 'no_such_bag'])
    assert exc.value.code == 2 and 'unknown bag' in capsys.readouterr().err


def test_deltas_say_what_moved_and_how_far():
    ref = {'a_rad': np.array([1.0, 2.0, 4.0]), 'b': np.array([1, 2]), 'c_rad': np.array([0.5]), 'gone': np.array(1),
           PROVENANCE: np.array('{}')}
    ours = {'a_rad': np.array([1.0, 2.5, 4.0]), 'b': np.array([1, 3]), 'c_rad': np.array([0.5]), 'new_s': np.array(2.0)}
    assert deltas(ours, ref) == ['  a_rad: 1 of 3 moved, max |change| 0.5 (0.12 of the largest |value|, 4)',
                                 '  b: 1 of 2 entries changed', '  gone: removed', '  new_s: new',
                                 '  1 quantities unchanged']


def test_the_comparison_catches_a_changed_output():
    ref, _ = read('carousel_vertical')
    ours = {k: v.copy() for k, v in ref.items()}
    key = 'auto.record.rate_body_rad_s'
    ours[key] = ours[key] * (1 + 4 * np.finfo(float).eps)
    assert differences(ours, ref, 'x') == []
    ours[key] = ref[key] * (1 + 1e-6)
    assert differences(ours, ref, 'x') == [f'x: {key} differs by up to '
                                           f'{np.max(np.abs(ref[key])) * 1e-6:.3g} '
                                           "(beyond rtol 1e-09 + 1e-12 of its unit's scale)"]
    ours[key] = ref[key]
    # a small field is held to the scale of its unit's largest (what it is computed from), no looser
    bias = 'auto.record.accel_bias_inplane_m_s2'
    atol = 1e-12 * np.nanmax(np.abs(ref['auto.record.specific_force_body_m_s2']))
    ours[bias] = ref[bias] + 0.5 * atol
    assert differences(ours, ref, 'x') == []
    ours[bias] = ref[bias] + 3 * atol
    assert differences(ours, ref, 'x')[0].startswith(f'x: {bias} differs by up to')
    ours[bias] = ref[bias]
    ours['auto.record.mode'] = np.where(ref['auto.record.mode'] == 'demodulated', 'pass_through',
                                        ref['auto.record.mode'])
    assert differences(ours, ref, 'x')[0].startswith('x: auto.record.mode differs at ')
    assert differences({**ref, PROVENANCE: np.array('{"commit": "other"}')}, ref, 'x') == []
