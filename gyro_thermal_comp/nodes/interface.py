"""What each node subscribes and publishes, declared once: topic, message type, QoS.

The nodes create their subscriptions and publishers from these tables; replay publishes a bag's
inputs and records a node's outputs from the same tables, so a topic or a type cannot differ
between the node and the tools around it. Topics are relative (remappable), but
`/diagnostics` (absolute, where aggregators read it) and `/tf`.

`imu/heading` is a `geometry_msgs/PoseWithCovarianceStamped` in the world frame (`fixed_frame`):
the type robot_localization and the navigation stack take a yaw from, with its covariance; only the
yaw and its variance are meaningful (position and roll/pitch variances are marked huge). `/tf`
(tf2_msgs/TFMessage, tf2_ros's dynamic-broadcaster QoS) is an output only where tf2_msgs is
installed (a ROS install; not in the PyPI wheels) and only with `publish_tf`.
"""
from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped, Vector3Stamped
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.publisher import Publisher
from rclpy.qos import QoSCompatibility, QoSProfile, ReliabilityPolicy, qos_check_compatible, qos_profile_sensor_data
from sensor_msgs.msg import Imu, JointState, MagneticField, Temperature

from .. import topics
from .parameters import OUTPUT_QUEUE_DEPTH
from .startup_report import InputWaitReport

try:   # in a ROS install; the PyPI wheels the venv holds have no tf2_msgs
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None


@dataclass(frozen=True)
class Port:
    """One topic of a node. Inputs are named after their `SensorChunk` stream; outputs use
    `depth` (reliable, keep-last) so a recorder or a controller does not lose samples."""
    name: str
    topic: str
    msg_type: type
    depth: int = 10

    @property
    def type_name(self) -> str:
        """'sensor_msgs/msg/Imu': the name bags and `ros2 topic` use."""
        return type_name(self.msg_type)


def type_name(msg_type: type) -> str:
    """A message class -> 'sensor_msgs/msg/Imu'."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


@dataclass(frozen=True)
class NodeInterface:
    node_name: str
    executable: str               # module in gyro_thermal_comp.nodes and the `ros2 run` name
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]

    def output(self, name: str) -> Port:
        return next(p for p in self.outputs if p.name == name)


def sensor_qos(depth: int, reliable: bool = False) -> QoSProfile:
    """Input QoS: sensor-data (best effort, volatile: matches reliable and best-effort drivers) with a
    queue deep enough for 1 kHz input while a batch is processed (rclpy's preset keeps only 5), or
    reliable (lossless through a stalled subscriber, but it matches reliable publishers only)."""
    reliability = ReliabilityPolicy.RELIABLE if reliable else qos_profile_sensor_data.reliability
    return QoSProfile(depth=depth, reliability=reliability, durability=qos_profile_sensor_data.durability,
                      history=qos_profile_sensor_data.history)


_DIAGNOSTICS = Port('diagnostics', topics.DIAGNOSTICS, DiagnosticArray)
# tf2_ros.TransformBroadcaster's QoS: reliable, volatile, keep last 100
_TF = (Port('tf', topics.TF, TFMessage, 100),) if TFMessage is not None else ()

STKF = NodeInterface(
    'stkf_drift_estimator', 'stkf_node',
    inputs=(Port('imu', topics.IMU_RAW, Imu), Port('mag', topics.MAG, MagneticField),
            Port('temperature', topics.TEMPERATURE, Temperature)),
    outputs=(Port('imu', topics.IMU_COMPENSATED, Imu, OUTPUT_QUEUE_DEPTH),
             Port('heading', topics.HEADING, PoseWithCovarianceStamped, OUTPUT_QUEUE_DEPTH), _DIAGNOSTICS, *_TF))

CAROUSEL = NodeInterface(
    'carousel_demodulator', 'carousel_node',
    inputs=(Port('imu', topics.IMU_RAW, Imu), Port('joint', topics.JOINT_STATES, JointState),
            Port('imu_aux', topics.IMU_AUX_RAW, Imu), Port('mag', topics.MAG, MagneticField),
            Port('temperature', topics.TEMPERATURE, Temperature)),
    outputs=(Port('imu', topics.IMU_DEMODULATED, Imu, 100),
             Port('gyro_bias', topics.CAROUSEL_GYRO_BIAS, Vector3Stamped, 100),
             Port('gyro_bias_sigma', topics.CAROUSEL_GYRO_BIAS_SIGMA, Vector3Stamped, 100), _DIAGNOSTICS))

NODES = {'stkf': STKF, 'carousel': CAROUSEL}


# rclpy gives every publisher and subscription default QoS-event handlers (a warning when an endpoint
# with an incompatible QoS or message type appears): two waitables each, which every executor turn
# walks in Python, the most costly entities of a wait (`benchmarks/live_latency.py --profile-node`
# prints a turn's cost). `quiet` creates none; such a node runs an `EndpointCheck` instead.
def _events(quiet: bool, kind):
    return kind(use_default_callbacks=False) if quiet else None


def create_publishers(node, interface: NodeInterface, skip=(), quiet: bool = False, depths=None) -> dict:
    """{output name: publisher} for every output of `interface` but those named in `skip`; `quiet`:
    without QoS-event handlers; `depths`: {output name: queue depth} instead of the port's."""
    depths = depths or {}
    return {p.name: node.create_publisher(p.msg_type, p.topic, QoSProfile(depth=depths.get(p.name, p.depth)),
                                          event_callbacks=_events(quiet, PublisherEventCallbacks))
            for p in interface.outputs if p.name not in skip}


def create_subscriptions(node, interface: NodeInterface, callbacks: dict, qos: QoSProfile, group,
                         raw: bool = False, quiet: bool = False) -> dict:
    """{stream: subscription} for every input, each with `callbacks[stream]`; `raw`: the callbacks
    get the serialized CDR bytes, not message objects; `quiet`: without QoS-event handlers."""
    return {p.name: node.create_subscription(p.msg_type, p.topic, callbacks[p.name], qos, callback_group=group,
                                             raw=raw, event_callbacks=_events(quiet, SubscriptionEventCallbacks))
            for p in interface.inputs}


class EndpointCheck:
    """What rclpy's default QoS-event handlers say, for a node created `quiet`: once per remote
    endpoint, a warning about a publisher on an input topic or a subscription on an output topic
    that can never be matched (another message type, or an incompatible reliability or durability:
    the policies sensor pipelines set; the graph reports deadline and liveliness in another form
    than a QoSProfile holds, so they are not compared). Run it now and then (the node: with its
    diagnostics); it looks at endpoints only when a topic has more than are matched."""

    def __init__(self, logger, node, subscriptions, publishers):
        self.logger, self.node = logger, node
        self.subscriptions, self.publishers = list(subscriptions), list(publishers)
        self._seen: set = set()     # endpoints already looked at (gid), compatible or not
        self.incompatible = 0

    def check(self) -> int:
        """Warn about the unmatched endpoints not seen before; returns how many were incompatible."""
        for sub in self.subscriptions:
            if self.node.count_publishers(sub.topic_name) > sub.get_publisher_count():
                for info in self.node.get_publishers_info_by_topic(sub.topic_name):
                    self._look(info, sub, 'publisher', 'offering', info.qos_profile, sub.qos_profile)
        for pub in self.publishers:
            if self.node.count_subscribers(pub.topic_name) > pub.get_subscription_count():
                for info in self.node.get_subscriptions_info_by_topic(pub.topic_name):
                    self._look(info, pub, 'subscription', 'requesting', pub.qos_profile, info.qos_profile)
        return self.incompatible

    def _look(self, info, ours, kind: str, verb: str, offered: QoSProfile, requested: QoSProfile) -> None:
        gid = bytes(info.endpoint_gid)
        if gid in self._seen:
            return
        if info.topic_type != type_name(ours.msg_type):
            problem = f'of type {info.topic_type}, not {type_name(ours.msg_type)}'
        else:
            compatibility, reason = qos_check_compatible(*(QoSProfile(depth=1, reliability=q.reliability,
                                                                      durability=q.durability)
                                                           for q in (offered, requested)))
            if compatibility != QoSCompatibility.ERROR:
                return     # compatible (or not decidable): matched soon, or never our concern
            problem = f"{verb} incompatible QoS ({reason.strip(';')})"
        self._seen.add(gid)
        self.incompatible += 1
        self.logger.warning(f"a {kind} on '{ours.topic_name}' {problem}: nothing goes between it and this node")


def unpublished(subscriptions: dict) -> set[str]:
    """Streams whose subscription has no matched publisher: nothing can arrive on them, so they hold
    no other stream back in the stamp merger."""
    return {stream for stream, sub in subscriptions.items() if sub.get_publisher_count() == 0}


def input_counters(merger, subscriptions: dict) -> dict[str, int]:
    """Diagnostic values of a node's input layer, under `input.` so they never hide the core's
    counters of the same names: the merger's counters and `input.<stream>_publishers`, the matched
    publishers of each subscription (zero: nothing feeds that input; a live replay waits for every
    input to be matched before it plays)."""
    values = {f'input.{k}': v for k, v in merger.counters().items()}
    values.update({f'input.{stream}_publishers': sub.get_publisher_count() for stream, sub in subscriptions.items()})
    return values


def output_counters(publishers: dict) -> dict[str, int]:
    """`output.<name>_subscribers`: the subscriptions each of a node's publishers has matched (a live
    replay waits until its recorder is matched on both sides before it plays: outputs are volatile).
    Stand-ins for publishers (replay's recorders) are left out."""
    return {f'output.{name}_subscribers': pub.get_subscription_count() for name, pub in publishers.items()
            if isinstance(pub, Publisher)}


def input_wait_report(node, subscriptions: dict, optional=()) -> InputWaitReport:
    """The node's "still waiting for data on X" report over its subscriptions' resolved topics."""
    return InputWaitReport(node.get_logger(), {s: sub.topic_name for s, sub in subscriptions.items()},
                           optional=optional)


def check_inputs_arrived(report: InputWaitReport, merger, subscriptions: dict, lock) -> None:
    """Feed `report` what each input received (the merger's counts, read under the node's `lock`) and
    how many publishers it has matched."""
    with lock:
        counts = merger.counters()
    report.check({s: counts[f'{s}_received'] for s in subscriptions},
                 {s: sub.get_publisher_count() for s, sub in subscriptions.items()})


# A node's `time_origin`: its pipeline's (the core runs on s since the first stamp; replay sets it).
pipeline_time_origin = property(lambda node: node.pipeline.time_origin,
                                lambda node, origin: setattr(node.pipeline, 'time_origin', origin),
                                doc="The pipeline's time origin (stamps.TimeOrigin).")
