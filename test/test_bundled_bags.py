"""The bundled bags are exactly what the commands in bags/manifest.json write.

A change to the simulator that alters the bags must come with regenerated bags (`make bags`).
"""
import json
import shlex

import numpy as np
import pytest

from conftest import BAGS, bundled_bags
from gyro_thermal_comp.bag_io import BagReader
from gyro_thermal_comp.cli import main

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
def test_bag_regenerates_identically(regenerated, name):
    ours, fresh = BAGS / name, regenerated / name
    with BagReader(ours) as a, BagReader(fresh) as b:
        assert [(t.topic, t.msgtype, t.count) for t in a.topics] == [(t.topic, t.msgtype, t.count) for t in b.topics]
        assert a.text('/sim/config') == b.text('/sim/config')
        for ca, cb in zip(a.chunks(600.0), b.chunks(600.0), strict=True):
            for stream, samples in ca.streams().items():
                other = getattr(cb, stream)
                for field in samples.__dataclass_fields__:
                    assert np.array_equal(getattr(samples, field), getattr(other, field)), (stream, field)
    # With the pinned rosbags the files are byte-identical too.
    assert (ours / f'{name}.mcap').read_bytes() == (fresh / f'{name}.mcap').read_bytes()
