"""The STKF node's three output sinks (nodes/output_sinks.py) publish the same numbers for the same
samples: CDR bytes to real publishers, message objects to stand-ins, replay's bulk records."""
import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu

from conftest import Capture
from gyro_thermal_comp import cdr
from gyro_thermal_comp.nodes.interface import STKF, TFMessage
from gyro_thermal_comp.nodes.output_arrays import BulkRecorder
from gyro_thermal_comp.nodes.output_sinks import BulkSink, CdrSink, MessageSink, output_sink
from gyro_thermal_comp.nodes.stkf_outputs import OneOutput, OutputArrays
from test_replay_bulk import _Records

FIXED, FRAME = 'odom', 'imu_link'


def _unit(rows: np.ndarray) -> np.ndarray:
    return rows / np.linalg.norm(rows, axis=1, keepdims=True)


def _arrays(n: int = 7) -> OutputArrays:
    """n samples of random numbers; every third without a header (as a replayed chunk has none)."""
    rng = np.random.default_rng(5)
    ns = 1_700_000_000_000_000_000 + np.cumsum(rng.integers(1, 30_000_000, n))
    headers = np.array([None if k % 3 == 0 else cdr.header_cdr(int(t), FRAME) for k, t in enumerate(ns)], object)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return OutputArrays(ns=ns, frame_id=FRAME, headers=headers, gyro=rng.normal(0, 0.1, (n, 3)),
                        accel=rng.normal(0, 1, (n, 3)) + [0, 0, 9.81], q_imu=_unit(rng.normal(size=(n, 4))),
                        q_heading=np.column_stack((np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2))),
                        orientation_var=rng.uniform(1e-6, 1e-2, (n, 3)), gyro_var=2.5e-5, accel_var=1.6e-3)


def _one(o: OutputArrays, k: int) -> OneOutput:
    return OneOutput(o.headers[k] or cdr.header_cdr(int(o.ns[k]), o.frame_id), tuple(o.gyro[k].tolist()),
                     o.accel[k].tolist(), tuple(o.q_imu[k].tolist()), tuple(o.orientation_var[k].tolist()),
                     o.gyro_var, o.accel_var, tuple(o.q_heading[k].tolist()))


def _real_publishers(node) -> tuple[dict, dict]:
    """imu and heading rclpy publishers whose publish keeps what it is given (bytes, from the CDR sink)."""
    pubs, kept = {}, {}
    for port in (STKF.output('imu'), STKF.output('heading')):
        pub = node.create_publisher(port.msg_type, port.topic, 10)
        kept[port.name] = []
        pub.publish = kept[port.name].append
        pub.get_subscription_count = lambda: 1
        pubs[port.name] = pub
    return pubs, kept


def test_the_three_sinks_publish_the_same_numbers(ros):
    import rclpy
    node = rclpy.create_node('output_sinks_test')
    o = _arrays()
    publish_tf = TFMessage is not None   # tf2_msgs comes with a ROS install
    real, raw = _real_publishers(node)
    stand_ins = {'imu': Capture(), 'heading': Capture()}
    records = _Records()
    recorder = BulkRecorder(records, STKF.output('imu'), STKF.output('heading'), FIXED)
    tfs = {name: Capture() for name in ('cdr', 'messages', 'bulk')}
    sinks = {name: output_sink({**pubs, 'tf': tfs[name]}, bulk, fixed_frame=FIXED, publish_tf=publish_tf,
                               heading_built=lambda: True)
             for name, pubs, bulk in (('cdr', real, None), ('messages', stand_ins, None),
                                      ('bulk', {'imu': Capture(), 'heading': Capture()}, recorder))}
    assert (type(sinks['cdr']), type(sinks['messages']), type(sinks['bulk'])) == (CdrSink, MessageSink, BulkSink)
    assert sinks['cdr'].heading_wanted() and sinks['messages'].heading_wanted() and sinks['bulk'].heading_wanted()
    for sink in sinks.values():
        sink.many(o)
    imu, heading = stand_ins['imu'].msgs, stand_ins['heading'].msgs
    assert len(imu) == len(heading) == len(raw['imu']) == len(raw['heading']) == o.ns.size
    assert [deserialize_message(m, Imu) for m in raw['imu']] == imu
    assert [deserialize_message(m, PoseWithCovarianceStamped) for m in raw['heading']] == heading
    assert [row[2] for row in records.rows] == [t for t in o.ns.tolist() for _ in (0, 1)]
    assert [deserialize_message(row[3], Imu) for row in records.rows[0::2]] == imu
    assert [deserialize_message(row[3], PoseWithCovarianceStamped) for row in records.rows[1::2]] == heading
    if publish_tf:
        assert len(tfs['cdr'].msgs) == o.ns.size and tfs['cdr'].msgs == tfs['messages'].msgs == tfs['bulk'].msgs
    # one sample at a time: the same messages again
    for k in range(o.ns.size):
        for sink in (sinks['cdr'], sinks['messages']):
            sink.one(_one(o, k))
    assert [deserialize_message(m, Imu) for m in raw['imu'][o.ns.size:]] == imu[o.ns.size:] == imu[:o.ns.size]
    assert heading[o.ns.size:] == heading[:o.ns.size]
    node.destroy_node()


def test_no_heading_while_the_pipeline_builds_none(ros):
    """A sink publishes imu/heading only while `heading_built()` says so; a real publisher wants it
    only while it has subscribers."""
    import rclpy
    node = rclpy.create_node('output_sinks_heading_test')
    real, raw = _real_publishers(node)
    real['heading'].get_subscription_count = lambda: 0
    stand_ins = {'imu': Capture(), 'heading': Capture()}
    cdr_sink, message_sink = (output_sink(pubs, fixed_frame=FIXED, publish_tf=False, heading_built=lambda: False)
                              for pubs in (real, stand_ins))
    assert not cdr_sink.heading_wanted() and message_sink.heading_wanted()
    o = _arrays(3)
    cdr_sink.many(o)
    message_sink.many(o)
    assert len(raw['imu']) == len(stand_ins['imu'].msgs) == 3 and raw['heading'] == stand_ins['heading'].msgs == []
    node.destroy_node()
