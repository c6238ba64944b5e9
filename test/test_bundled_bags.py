"""The bundled bags are what the commands in bags/manifest.json write, on any CPU.

A change to the simulator that alters the bags must come with regenerated bags (`make bags`).
Structure (topics, types, counts, configuration keys and integers, stamps) must match exactly; values
and configuration floats to rounding
(`gyro_thermal_comp.bag_compare`: another CPU's numpy SIMD and OpenBLAS kernels round differently).
"""
import json
import shlex

import numpy as np
import pytest

from conftest import BAGS, bundled_bags
from gyro_thermal_comp.bag_compare import bag_differences, config_differences
from gyro_thermal_comp.bag_io import BagReader, BagWriter
from gyro_thermal_comp.cli import main
from gyro_thermal_comp.samples import SensorChunk
from gyro_thermal_comp.topics import SIM_CONFIG

MANIFEST = json.loads((BAGS / 'manifest.json').read_text())['bags']


def test_manifest_covers_every_bundled_bag():
    assert sorted(e['name'] for e in MANIFEST) == sorted(p.name for p in bundled_bags())
    readme = (BAGS / 'README.md').read_text()
    for entry in MANIFEST:
        assert shlex.split(entry['command'])[:2] == ['gyro-thermal-comp', 'simulate']
        assert entry['command'] in readme, f'bags/README.md does not show the command for {entry["name"]}'


@pytest.fixture(scope='module')
def regenerated(tmp_path_factory):
    out = tmp_path_factory.mktemp('regen')
    assert main(['bundle', str(BAGS), '--out', str(out)]) == 0
    return out


@pytest.mark.parametrize('name', [e['name'] for e in MANIFEST])
def test_bag_regenerates(regenerated, name):
    problems = bag_differences(BAGS / name, regenerated / name)
    assert not problems, '\n'.join(problems)


def _perturbed_copy(src, dst, relative: float):
    """`src` rewritten with the ground-truth gyro bias scaled by (1 + relative)."""
    with BagReader(src) as reader, BagWriter(dst, time_origin_ns=reader.time_origin_ns) as writer:
        for text in reader.text(SIM_CONFIG):
            writer.write_text(SIM_CONFIG, reader.start_time_s, text)
        for chunk in reader.chunks(600.0):
            streams = chunk.streams()
            if 'gyro_bias' in streams:
                bias = streams['gyro_bias']
                streams['gyro_bias'] = type(bias)(bias.t, bias.vec * (1.0 + relative))
            writer.write_chunk(SensorChunk(**streams))


def test_comparison_tolerates_last_bits_and_catches_real_differences(regenerated, tmp_path):
    """A few ulps (what another CPU gives) pass; 1e-6 relative (a real change) fails, naming the bag,
    the stream and the worst difference."""
    name = 'null'
    ulps = 4 * np.finfo(float).eps
    _perturbed_copy(regenerated / name, tmp_path / 'ulps', ulps)
    assert bag_differences(BAGS / name, tmp_path / 'ulps') == []
    _perturbed_copy(regenerated / name, tmp_path / 'real', 1e-6)
    problems = bag_differences(BAGS / name, tmp_path / 'real')
    assert len(problems) == 1 and 'gyro_bias.vec differs' in problems[0] and 'real' in problems[0], problems
    worst = float(problems[0].split('by up to ')[1].split()[0])
    with BagReader(BAGS / name) as reader:
        scale = max(np.max(np.abs(c.gyro_bias.vec)) for c in reader.chunks(600.0, streams=['gyro_bias']))
    assert worst == pytest.approx(1e-6 * scale, rel=0.01)    # the message reports the real difference


def test_structure_must_match_exactly(regenerated, tmp_path):
    with (BagReader(regenerated / 'null') as reader,
          BagWriter(tmp_path / 'short', time_origin_ns=reader.time_origin_ns) as writer):
        for text in reader.text(SIM_CONFIG):
            writer.write_text(SIM_CONFIG, reader.start_time_s, text)
        writer.write_chunk(next(reader.chunks(600.0)))           # the first 10 minutes only
    problems = bag_differences(BAGS / 'null', tmp_path / 'short')
    assert problems and 'counts differ' in problems[0]


def test_configuration_floats_tolerate_last_bits_and_the_rest_must_match():
    """A regenerated bag's /sim/config holds floats numpy derived from random draws (a unit's
    hard-iron vector), whose last bits depend on the CPU: those get rtol, nothing else does."""
    ours = json.dumps({'unit': {'mag_hard_iron_ut': [0.1, -2.5, 1e-20], 'seed': 3}, 'name': 'x'})
    ulps = json.dumps({'unit': {'mag_hard_iron_ut': [0.1 * (1 + 4e-16), -2.5, 1e-20], 'seed': 3}, 'name': 'x'})
    assert config_differences([ours], [ulps]) == []
    real = json.dumps({'unit': {'mag_hard_iron_ut': [0.1 * (1 + 1e-6), -2.5, 1e-20], 'seed': 3}, 'name': 'x'})
    assert config_differences([ours], [real]) == [
        f"/unit/mag_hard_iron_ut[0]: {0.1 * (1 + 1e-6)!r} != 0.1 (beyond rtol 1e-09)"]
    for other in ({'unit': {'mag_hard_iron_ut': [0.1, -2.5, 1e-20], 'seed': 4}, 'name': 'x'},
                  {'unit': {'mag_hard_iron_ut': [0.1, -2.5, 1e-20], 'seed': 3}, 'name': 'y'},
                  {'unit': {'mag_hard_iron_ut': [0.1, -2.5], 'seed': 3}, 'name': 'x'},
                  {'unit': {'mag_hard_iron_ut': [0.1, -2.5, 1e-20], 'seed': 3.0}, 'name': 'x'}):
        assert len(config_differences([ours], [json.dumps(other)])) == 1, other
