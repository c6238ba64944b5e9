"""Results do not depend on the epoch of the stamps.

The first SLICE_S of the bundled vehicle_loop bag is written three times: stamped from 1970-01-01
(epoch 0), from the simulator's epoch (2024-01-01T00:00:00Z) and from that epoch plus an odd
13.7 h (a real log starts at any time, to the ns). The STKF's outputs (heading, compensated gyro,
learned parameters, the evaluation scores) through the offline evaluate path, and stkf_node's
outputs through the in-process replay, must be bit-identical: readers hand the core seconds since
the bag's first message (gyro_thermal_comp/stamps.py). As absolute float seconds, what the readers
gave before, the same 1800 s bag at the epoch moved the STKF heading by up to 0.04 rad and flipped
the magnetic gate at 117 of 4500 compared samples.
"""
from itertools import takewhile

import numpy as np
import pytest

from conftest import BAGS
from gyro_thermal_comp.angles import yaw_from_quat
from gyro_thermal_comp.bag_io import BagReader, BagWriter, read_chunks
from gyro_thermal_comp.bag_storage import RELIABLE, SENSOR_DATA
from gyro_thermal_comp.evaluation.report import evaluate
from gyro_thermal_comp.nodes.replay import replay
from gyro_thermal_comp.samples import SensorChunk, slice_samples
from gyro_thermal_comp.sim import EPOCH_NS
from gyro_thermal_comp.thermal.estimator import EstimatorConfig, ThermalDriftEstimator

SLICE_S = 240.0                  # still period, then 20 filter windows
REPLAY_S = 60.0                  # the node in-process is slower: its first minute
ODD_NS = 49_327_123_456_789      # 13 h 42 min 7.123456789 s
SHIFTS_NS = {'epoch0': 0, 'epoch': EPOCH_NS, 'epoch_odd': EPOCH_NS + ODD_NS}


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """name -> the slice with its first message at SHIFTS_NS[name]."""
    with BagReader(BAGS / 'vehicle_loop') as reader:
        chunks = [SensorChunk(**{k: slice_samples(v, v.t < SLICE_S) for k, v in c.streams().items()})
                  for c in takewhile(lambda c: c.imu.t[0] < SLICE_S, reader.chunks(60.0))]
    assert chunks[0].imu.t[0] == 0.0
    out = {}
    for name, origin_ns in SHIFTS_NS.items():
        out[name] = tmp_path_factory.mktemp('epoch') / name
        with BagWriter(out[name], time_origin_ns=origin_ns) as writer:
            for c in chunks:
                writer.write_chunk(c)
    return out


def test_slices_start_at_their_epoch(bags):
    for name, origin_ns in SHIFTS_NS.items():
        with BagReader(bags[name]) as reader:
            assert reader.time_origin_ns == origin_ns and reader.start_time_s == 0.0
            first = next(reader.messages(['/imu/data_raw']))[3].header.stamp
            assert first.sec * 1_000_000_000 + first.nanosec == origin_ns


def _offline(bag):
    """STKF outputs over the bag (t, heading, compensated gyro, parameters) and its evaluate() scores."""
    est = ThermalDriftEstimator(EstimatorConfig())
    outs = [est.process(c) for c in read_chunks(bag, 60.0)]
    columns = [np.concatenate([o.track.t for o in outs]), np.concatenate([o.track.heading_rad for o in outs]),
               np.vstack([o.gyro_compensated for o in outs]), np.vstack([o.params for o in outs])]
    report = evaluate(lambda: read_chunks(bag, 60.0), [ThermalDriftEstimator(EstimatorConfig())]).to_dict()
    for key in ('fit_time_s', 'update_time_s'):    # wall times
        report.pop(key)
    for scores in report['methods'].values():
        scores.pop('update_samples_per_s', None)
    return columns, report


def _replayed(bag, out):
    """stkf_node in-process over the bag's first REPLAY_S: /imu/data stamps (s since the output's
    first message), heading (yaw of the orientation) and angular velocity."""
    replay(bag, out, duration_s=REPLAY_S)
    t, heading, gyro = [], [], []
    with BagReader(out) as reader:
        for _, _, _, m in reader.messages(['/imu/data']):
            q, w = m.orientation, m.angular_velocity
            t.append(reader.stamp_s(m.header))
            heading.append(yaw_from_quat([q.x, q.y, q.z, q.w]))
            gyro.append([w.x, w.y, w.z])
    return np.array(t), np.array(heading), np.array(gyro)


def test_offline_outputs_do_not_depend_on_the_epoch(bags):
    columns0, report0 = _offline(bags['epoch0'])
    assert len(columns0[0]) == SLICE_S * 50 and np.isfinite(columns0[3][-1]).all()
    for name in ('epoch', 'epoch_odd'):
        columns, report = _offline(bags[name])
        for a, b in zip(columns, columns0):
            assert np.array_equal(a, b, equal_nan=True), name
        assert report == report0, name


def test_replayed_outputs_do_not_depend_on_the_epoch(bags, tmp_path):
    t0, h0, g0 = _replayed(bags['epoch0'], tmp_path / 'out0')
    assert len(t0) == len(h0) == REPLAY_S * 50
    t, h, g = _replayed(bags['epoch_odd'], tmp_path / 'out_odd')
    assert np.array_equal(t, t0) and np.array_equal(h, h0) and np.array_equal(g, g0)
    with BagReader(tmp_path / 'out_odd') as reader:     # the replay bag offers what the publishers did
        info = {i.topic: i for i in reader.topics}
    assert info['/imu/data_raw'].offered_qos == (SENSOR_DATA,) and info['/imu/data'].offered_qos == (RELIABLE,)
    assert all(i.type_hash.startswith('RIHS01_') for i in info.values())
