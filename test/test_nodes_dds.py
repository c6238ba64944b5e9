"""Real DDS on loopback: a bag published into a running node, and the `ros2 run` route.

ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a ROS_DOMAIN_ID of this test session (conftest).
"""
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile

from conftest import BAGS, PKG, Freezer, installed_env
from gyro_thermal_comp.angles import wrap_angle, yaw_from_quat
from gyro_thermal_comp.bag_io import BagReader, read_chunks
from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
from gyro_thermal_comp.nodes.replay import replay
from gyro_thermal_comp.samples import SensorChunk, slice_samples
from gyro_thermal_comp.thermal.compensator import ThermalCompensator

SECONDS = 40.0


def offline(bag, seconds):
    """The core alone over the same samples, as the node composes it (estimator + fast path): no ROS,
    one pass, 10 s chunks. Returns stamps (ns), compensated rates, headings of the outputs."""
    values = {s.name: s.default for s in all_specs()}
    comp = ThermalCompensator(config_from_params(values), values['output_delay_s'])
    outs = []
    with BagReader(bag) as reader:    # the node's times are s since the bag's first message
        for chunk in reader.chunks(10.0, streams=['imu', 'mag', 'temperature']):
            outs.append(comp.run(SensorChunk(**{k: slice_samples(v, v.t < seconds)
                                                for k, v in chunk.streams().items()}), reader.time_origin_ns))
    comp.finish()
    outs.append(comp.take_ready()[1])
    outs = [o for o in outs if o is not None]
    ok = np.concatenate([o.ok for o in outs])
    return (np.concatenate([o.ns for o in outs])[ok], np.vstack([o.gyro_compensated for o in outs])[ok],
            np.concatenate([o.heading for o in outs])[ok])


@pytest.mark.parametrize('executor', ['single', 'events'])
def test_live_node_matches_offline_core(tmp_path, executor):
    """Live outputs equal the offline core's (to 1e-12 rad/s; headings to 1e-9 rad, the quaternion
    round trip), the node frozen three times for 3 s as a loaded CPU would (see
    test_carousel_node_bags.test_live_dds_run_matches_in_process); with either executor the node
    can spin (`stkf_node --executor`)."""
    out = tmp_path / 'live'
    with Freezer('gyro_thermal_comp.nodes.stkf_node') as freezer:
        counts = replay(BAGS / 'vehicle_loop', out, live=True, rate=1.0, duration_s=SECONDS, executor=executor)
    assert freezer.frozen >= 1
    n_in = counts['/imu/data_raw']
    assert counts['/imu/data'] == n_in, 'the node dropped samples at the bag rate'
    rates, headings, stamps = [], [], []
    with BagReader(out) as reader:
        for topic, _, t_ns, msg in reader.messages(['/imu/data', '/imu/heading']):
            if topic == '/imu/data':
                rates.append([msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z])
                stamps.append(t_ns)
            else:
                q = msg.pose.pose.orientation
                headings.append(yaw_from_quat([q.x, q.y, q.z, q.w]))
    ns, gyro, heading = offline(BAGS / 'vehicle_loop', SECONDS)
    assert len(stamps) == len(ns), f'recorded {len(stamps)} imu/data of the {len(ns)} the core gives'
    assert len(headings) == len(ns), f'recorded {len(headings)} imu/heading of the {len(ns)} the core gives'
    assert np.array_equal(ns, stamps)
    assert np.max(np.abs(np.array(rates) - gyro)) < 1e-12
    assert np.max(np.abs(wrap_angle(np.array(headings) - heading))) < 1e-9


def test_ros2_run_route_with_params_file_and_remap(colcon_install):
    from ament_index_python.packages import get_package_prefix, get_package_share_directory
    env = installed_env(colcon_install)
    os.environ['AMENT_PREFIX_PATH'] = env['AMENT_PREFIX_PATH']
    exe = Path(get_package_prefix(PKG)) / 'lib' / PKG / 'stkf_node'          # how ros2 run finds it
    params = Path(get_package_share_directory(PKG)) / 'config' / 'stkf.yaml'
    assert exe.is_file() and params.is_file()
    proc = subprocess.Popen([sys.executable, str(exe), '--ros-args', '--params-file', str(params),
                             '-r', 'imu/data_raw:=/other/topic'], env=env, stderr=subprocess.PIPE, text=True)
    rclpy.init()
    executor = SingleThreadedExecutor()
    try:
        from sensor_msgs.msg import Imu, MagneticField, Temperature
        node = rclpy.create_node('ros2_run_probe')
        pubs = {'imu': node.create_publisher(Imu, '/other/topic', 100),
                'mag': node.create_publisher(MagneticField, 'imu/mag', 100),
                'temperature': node.create_publisher(Temperature, 'imu/temperature', 100)}
        unmapped = node.create_publisher(Imu, 'imu/data_raw', 10)
        got = []
        node.create_subscription(Imu, 'imu/data', got.append, QoSProfile(depth=1000))
        executor.add_node(node)
        threading.Thread(target=executor.spin, daemon=True).start()
        end = time.monotonic() + 30
        while time.monotonic() < end and not all(p.get_subscription_count() for p in pubs.values()):
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.1)
        assert pubs['imu'].get_subscription_count() == 1     # it subscribes to the remapped topic...
        assert unmapped.get_subscription_count() == 0       # ...and not to the default one
        from gyro_thermal_comp.nodes.replay import _messages
        chunk = next(read_chunks(BAGS / 'vehicle_loop', 5.0, streams=['imu', 'mag', 'temperature']))
        for _, stream, msg in _messages(chunk, ('imu', 'mag', 'temperature')):
            pubs[stream].publish(msg)
            time.sleep(0.002)
        end = time.monotonic() + 10
        while time.monotonic() < end and len(got) < len(chunk.imu.t) // 2:
            time.sleep(0.1)
        assert len(got) > 0, 'the ros2-run node published nothing'
    finally:
        executor.shutdown()  # before the context goes, or the spinning thread raises
        rclpy.try_shutdown()
        proc.terminate()
        proc.wait(timeout=10)
