"""Replay writes the STKF node's outputs in bulk (nodes/output_arrays.py): the same messages as
publishing them one by one, value for value."""
from conftest import BAGS, Capture
from gyro_thermal_comp.bag_io import TYPESTORE, read_chunks
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.nodes.interface import STKF
from gyro_thermal_comp.nodes.output_arrays import BulkRecorder


class _Records:
    """Stands in for a BagWriter: keeps (topic, type, log time, bytes)."""

    def __init__(self):
        self.rows = []

    def write_raw(self, topic, msgtype, t_ns, data):
        self.rows.append((topic, msgtype, t_ns, data))


def _xyz(v):
    return [v.x, v.y, v.z] + ([v.w] if hasattr(v, 'w') else [])


def _numbers(msg) -> dict:
    """What an Imu or PoseWithCovarianceStamped carries (rclpy or rosbags object)."""
    h = msg.header
    out = {'stamp': h.stamp.sec * 1_000_000_000 + h.stamp.nanosec, 'frame_id': h.frame_id}
    if hasattr(msg, 'angular_velocity'):
        out.update(q=_xyz(msg.orientation), q_cov=list(msg.orientation_covariance), w=_xyz(msg.angular_velocity),
                   w_cov=list(msg.angular_velocity_covariance), a=_xyz(msg.linear_acceleration),
                   a_cov=list(msg.linear_acceleration_covariance))
    else:
        out.update(p=_xyz(msg.pose.pose.position), q=_xyz(msg.pose.pose.orientation), cov=list(msg.pose.covariance))
    return {k: [float(x) for x in v] if isinstance(v, list) else v for k, v in out.items()}


def test_bulk_outputs_equal_the_messages_published_one_by_one(ros):
    one_by_one, bulk = make_stkf_node(), make_stkf_node()
    one_by_one.pubs = {name: Capture() for name in one_by_one.pubs}
    bulk.pubs = {name: Capture() for name in bulk.pubs}
    records = _Records()
    bulk.bulk_sink = BulkRecorder(records, STKF.output('imu'), STKF.output('heading'), bulk.settings['fixed_frame'])
    for chunk in read_chunks(BAGS / 'vehicle_loop', 10.0, streams=['imu', 'mag', 'temperature']):
        if chunk.imu.t[0] >= 60.0:
            break
        one_by_one.process_chunk(chunk)
        bulk.process_chunk(chunk)
    one_by_one.shutdown()
    bulk.shutdown()
    imu, heading = one_by_one.pubs['imu'].msgs, one_by_one.pubs['heading'].msgs
    one_by_one.destroy_node()
    bulk.destroy_node()
    assert len(imu) > 2000 and len(records.rows) == 2 * len(imu)
    assert bulk.outputs_published == one_by_one.outputs_published == len(imu)
    for k, (msg, head) in enumerate(zip(imu, heading)):
        for expected, (topic, msgtype, t_ns, data) in ((msg, records.rows[2 * k]), (head, records.rows[2 * k + 1])):
            got = TYPESTORE.deserialize_cdr(data, msgtype)
            a, b = _numbers(expected), _numbers(got)
            assert a == b, (topic, k)
            assert t_ns == a['stamp']
