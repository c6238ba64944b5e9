"""The carousel node's pipeline without ROS: samples pushed one at a time, in stamp order, through
each stream's guard and the stamp merger, give the records the demodulator gives for the same
samples as one offline chunk; a NaN sample is dropped by its guard and counted once. The pipeline
module itself loads no ROS package (the node's parameter table, used here for the defaults, does)."""
import math
import subprocess
import sys
from dataclasses import fields

import numpy as np

from conftest import BAGS
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator
from gyro_thermal_comp.nodes.carousel_node import carousel_specs
from gyro_thermal_comp.nodes.carousel_pipeline import CarouselPipeline
from gyro_thermal_comp.nodes.interface import CAROUSEL
from gyro_thermal_comp.nodes.parameters import config_from_params
from gyro_thermal_comp.samples import ImuSamples, SensorChunk

STREAMS = ('imu', 'joint', 'temperature')
SECONDS = 90.0   # the still start, the spin-up and a dozen revolutions (demodulated from 66 s)


def _rows(chunk: SensorChunk):
    """(t, stream, row) of every sample, in stamp order, in the row layouts the node pushes."""
    items = [(t, 'imu', list(g) + list(a)) for t, g, a in zip(chunk.imu.t, chunk.imu.gyro, chunk.imu.accel)]
    items += [(t, 'joint', [p, v]) for t, p, v in zip(chunk.joint.t, chunk.joint.position, chunk.joint.velocity)]
    items += [(t, 'temperature', [c]) for t, c in zip(chunk.temperature.t, chunk.temperature.temp_c)]
    return sorted(items, key=lambda item: item[0])


def test_pushed_samples_give_the_offline_records_and_a_nan_is_counted_once():
    values = {s.name: s.default for s in carousel_specs()}
    config = config_from_params(values, CarouselConfig.turntable())
    chunk = next(read_chunks(BAGS / 'carousel_vertical', SECONDS, streams=list(STREAMS)))
    # a NaN IMU sample between two real ones: the offline run gets it too, and drops it as well
    k = 1000
    t_nan = 0.5 * (chunk.imu.t[k] + chunk.imu.t[k + 1])
    nan = np.full((1, 3), np.nan)
    chunk = SensorChunk(imu=ImuSamples(np.insert(chunk.imu.t, k + 1, t_nan), np.insert(chunk.imu.gyro, k + 1, nan, 0),
                                       np.insert(chunk.imu.accel, k + 1, nan, 0)),
                        joint=chunk.joint, temperature=chunk.temperature)

    pipeline = CarouselPipeline(config, values, [p.name for p in CAROUSEL.inputs])
    outs, kept = [], 0
    for n, (t, stream, row) in enumerate(_rows(chunk)):
        accepted = pipeline.push(stream, float(t), row)
        assert accepted == all(math.isfinite(v) for v in row)
        kept += accepted and stream == 'imu'
        if n % 100 == 0:   # the node's timer
            outs.append(pipeline.poll())
    outs += [pipeline.poll(flush=True), pipeline.finish()]
    outs = [o for o in outs if o is not None]
    records = [r for o in outs for r in o.records]

    reference = CarouselDemodulator(config)
    expected = list(reference.update(chunk).records) + list(reference.flush().records)
    assert len(records) == len(expected) > 30
    for got, want in zip(records, expected):   # exactly equal: the output does not depend on batching
        for f in fields(want):
            np.testing.assert_array_equal(getattr(got, f.name), getattr(want, f.name), err_msg=f.name)

    diag = pipeline.diagnostics()
    assert diag.values['core.imu_dropped_nonfinite'] == 1 == reference.counts['imu_dropped_nonfinite']
    merged = pipeline.merger.counters()      # the NaN never reached the stamp merger
    assert kept == chunk.imu.t.size - 1 and merged['imu_dropped_late'] == 0
    assert merged['imu_received'] == chunk.imu.t.size           # the NaN sample arrived too
    assert diag.state == {'mode': 'pass_through', 'reason': 'end of data: partial revolution'}
    assert not diag.demodulating and diag.message == 'pass-through: end of data: partial revolution'
    assert sum(r.mode == 'demodulated' for r in records) >= 10
    published = [p for o in outs for p in pipeline.outputs(o)]
    assert len(published) == len(records)
    assert all(np.all(np.isfinite(p.rate_variances)) and np.all(p.rate_variances > 0) for p in published)


def test_the_pipeline_loads_no_ros_module():
    code = ('import sys, gyro_thermal_comp.nodes.carousel_pipeline\n'
            'print(sorted(m for m in sys.modules if m.split(".")[0] in ("rclpy", "rosidl_parser", "builtin_interfaces",'
            ' "std_msgs", "sensor_msgs", "geometry_msgs", "diagnostic_msgs")))')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == '[]'
