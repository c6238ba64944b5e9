"""Run a node over a bag and record inputs + outputs into a new bag.

Default (in-process): the node object is built as for `ros2 run` (same class, same parameters) and
fed the bag's samples directly, in stamp order, with the bag's timestamps; its publishers are
replaced by recorders. Deterministic and much faster than real time.

`live=True`: the node runs as its own process (`python -m gyro_thermal_comp.nodes.<node>`, what the
`ros2 run` executable starts), the bag is published over real DDS (loopback) by rclpy publishers at
`rate` x real time, and a recorder subscribes to the node's outputs.
"""
from __future__ import annotations

import contextlib
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
import yaml
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState, MagneticField, Temperature
from std_msgs.msg import Header

from .. import topics
from ..bag_io import BagReader, BagWriter
from ..progress import progress
from ..samples import SensorChunk, slice_samples
from ..stamps import TimeOrigin
from . import conversions as conv
from .executors import executor_problem
from .interface import NODES, NodeInterface
from .output_arrays import BulkRecorder


class _BagRecorder:
    """Stands in for a publisher: serialises the rclpy message and writes it at its header stamp."""

    def __init__(self, writer: BagWriter, port, lock: threading.Lock | None = None):
        self.writer, self.topic, self.msgtype = writer, '/' + port.topic.lstrip('/'), port.type_name
        self.lock = lock or contextlib.nullcontext()  # live: the player thread writes inputs too
        self.count = 0

    def publish(self, msg) -> None:
        stamp = conv.message_stamp(msg)   # header stamp; a TFMessage's first transform's
        data = serialize_message(msg)
        with self.lock:
            self.writer.write_raw(self.topic, self.msgtype, stamp.sec * 1_000_000_000 + stamp.nanosec, data)
        self.count += 1


def _make_node(kind: str, context: Context):
    if kind == 'stkf':
        from .stkf_node import StkfDriftEstimatorNode as cls
    elif kind == 'carousel':
        from .carousel_node import CarouselDemodulatorNode as cls
    else:
        raise ValueError(f'unknown node {kind!r}; choose from {sorted(NODES)}')
    return cls(context=context)


def _ros_args(params_file, overrides: dict | None = None) -> list[str]:
    args = []
    if params_file is not None:
        if not Path(params_file).is_file():
            raise ValueError(f'parameter file {params_file} does not exist')
        try:   # rcl would say it from C, with a traceback after it
            yaml.safe_load(Path(params_file).read_text())
        except yaml.YAMLError as exc:
            raise ValueError(f'parameter file {params_file} is not valid YAML: {exc}') from None
        args += ['--params-file', str(params_file)]
    for name, value in (overrides or {}).items():
        args += ['-p', f'{name}:={value}']
    return ['--ros-args', *args] if args else []


# Live replay is an evaluation: the node must see every sample, in stamp order, however a loaded CPU
# times delivery. The player is reliable and the node subscribes reliably (a stalled node loses nothing
# in transport), and it waits for a late topic as long as it takes (a reliable writer may resend
# seconds after a stall), its first samples included. Queues on both sides hold 10 s of a 1 kHz IMU,
# the STKF node's per-sample outputs too (a node frozen for seconds publishes them in one burst, and a
# reliable keep-last writer overwrites what its queue cannot hold), and a stopping node waits for the
# recorder's acknowledgements as long as a starved machine needs (below the stop's hang guard).
# Streams the bag does not have get no publisher, so they hold nothing back.
_LIVE_QUEUE_DEPTH = 10000
_LIVE_OVERRIDES = {'reliable_inputs': 'true', 'max_latency_s': '60.0', 'first_sample_wait_s': '60.0',
                   'input_queue_depth': str(_LIVE_QUEUE_DEPTH)}
_LIVE_NODE_OVERRIDES = {'stkf': {'output_queue_depth': str(_LIVE_QUEUE_DEPTH), 'stop_delivery_wait_s': '120.0'}}


def _limit(chunk: SensorChunk, span: tuple[float, float]) -> SensorChunk:
    """The samples in [start, end) of `span` (-inf, inf: all)."""
    t_start, t_end = span
    if t_start == -np.inf and t_end == np.inf:
        return chunk
    return SensorChunk(**{name: slice_samples(s, (s.t >= t_start) & (s.t < t_end))
                          for name, s in chunk.streams().items()})


def _limit_raw(raw, span: tuple[float, float], reader: BagReader):
    """The records `_limit` keeps (their stamps as the same floats as chunk times), under the
    package's topic names whatever the bag calls them (reader.topic_map)."""
    raw = raw.renamed({topic: topics.BAG_STREAMS[name][0] for name, topic in reader.topic_map.items()
                       if topic != topics.BAG_STREAMS[name][0]})
    t_start, t_end = span
    if t_start == -np.inf and t_end == np.inf:
        return raw
    return raw.select((raw.stamp_s >= t_start) & (raw.stamp_s < t_end))


def replay(bag, out, *, node: str = 'stkf', params_file=None, live: bool = False, rate: float = 1.0,
           duration_s: float | None = None, overwrite: bool = False, model_file=None,
           executor: str = 'single', topic_map: dict[str, str] | None = None, start_s: float = 0.0,
           summary: list | None = None) -> dict[str, int]:
    """Replay `bag` through a node into `out` (inputs + outputs). Returns message counts per topic.
    `model_file`: the stkf node's drift_model_file parameter (a drift model YAML). `executor`: the
    live node's --executor (nodes/executors.py). `topic_map`: the bag's topics per stream where they
    are not the package's (BagReader); the inputs are written under the package's names. `start_s`:
    begin this many seconds into the bag (the node starts there, as a node restarted on a moving
    vehicle). `summary`: a list that gets the stkf node's last word on learning ('learning: N filter
    updates ...' or 'not learning: why')."""
    if not (start_s >= 0.0 and start_s < float('inf')):
        raise ValueError(f'start must be a number of seconds >= 0, got {start_s}')
    problem = executor_problem(executor)
    if problem:
        raise ValueError(problem)
    if node not in NODES:
        raise ValueError(f'unknown node {node!r}; choose from {sorted(NODES)}')
    if model_file is not None and node != 'stkf':
        raise ValueError('a drift model file is for the stkf node')
    overrides = {} if model_file is None else {'drift_model_file': str(Path(model_file).resolve())}
    context = Context()
    rclpy.init(args=_ros_args(params_file, overrides), context=context)
    try:
        # The output is checked up front and written under a temporary name, renamed to `out` only
        # when the replay succeeds (bag_io.BagWriter): a failed replay leaves nothing at `out`.
        writer = BagWriter(out, overwrite=overwrite)
        with BagReader(bag, topic_map) as reader:
            reader.require('imu')  # an unusable bag is an error before the node starts, not an empty output
            writer.time_origin_ns = reader.time_origin_ns   # inputs and outputs at the bag's own stamps
            with writer:
                for text in reader.text(topics.SIM_CONFIG):
                    writer.write_text(topics.SIM_CONFIG, reader.start_time_s, text)
                if start_s >= reader.duration_s:
                    raise ValueError(f'start {start_s:g} s is beyond the end of {bag} ({reader.duration_s:.0f} s)')
                t_start = reader.start_time_s + start_s if start_s > 0 else -np.inf
                t_end = np.inf if duration_s is None else reader.start_time_s + start_s + duration_s
                total = min(reader.duration_s - start_s, duration_s or reader.duration_s)
                span = (t_start, t_end)
                if live:
                    said = _replay_live(node, reader, writer, span, total, rate, context, params_file, overrides,
                                        executor)
                else:
                    node_obj = _make_node(node, context)
                    try:
                        _replay_in_process(node, node_obj, reader, writer, span, total)
                        said = node_obj.learning_summary() if node == 'stkf' else None
                    finally:
                        node_obj.destroy_node()
                if summary is not None and said:
                    summary.append(f'{NODES[node].executable}: {said}')
        return dict(writer.counts)
    finally:
        rclpy.try_shutdown(context=context)


def _replay_in_process(kind, node_obj, reader, writer, span, total) -> None:
    interface = NODES[kind]
    inputs = [p.name for p in interface.inputs]
    node_obj.pubs = {p.name: _BagRecorder(writer, p) for p in interface.outputs}
    if kind == 'stkf':   # its per-sample outputs as arrays, encoded in bulk (output_arrays.py)
        node_obj.bulk_sink = BulkRecorder(writer, interface.output('imu'), interface.output('heading'),
                                          node_obj.settings['fixed_frame'])
    node_obj.time_origin = TimeOrigin(reader.time_origin_ns)   # chunk times are s since it
    next_diag = None
    with progress(total=total, desc=f'replay {kind}') as bar:
        for chunk, raw in reader.chunks(10.0, keep_raw=True):
            chunk, raw = _limit(chunk, span), _limit_raw(raw, span, reader)
            writer.write_raw_records(raw)     # the inputs as recorded, not re-serialised
            feed = SensorChunk(**{k: v for k, v in chunk.streams().items() if k in inputs and len(v.t)})
            if feed.imu is None:
                continue
            node_obj.process_chunk(feed)
            # diagnostics once per second of bag time, stamped with bag time (deterministic)
            t_last = float(feed.imu.t[-1])
            next_diag = t_last if next_diag is None else next_diag
            while next_diag <= t_last:
                level, message, values = node_obj.diagnostic_values()
                stamp = conv.time_msg(next_diag, node_obj.time_origin)
                node_obj.pubs['diagnostics'].publish(conv.diagnostic_array(stamp, node_obj.get_name(),
                                                                node_obj.hardware_id, level, message, values))
                next_diag += node_obj.settings['diagnostics_period_s']
            bar.update_to(t_last - reader.start_time_s)
    node_obj.shutdown()


class _Player(Node):
    """Publishes bag samples as ROS messages (what a sensor driver would do) and watches the node's
    diagnostics, which say how many publishers each input has matched and how much it received."""

    def __init__(self, context: Context, interface: NodeInterface, present):
        """Publishes the node's inputs that the bag has (`present`: stream names)."""
        super().__init__('gtc_bag_player', context=context)
        qos = QoSProfile(depth=_LIVE_QUEUE_DEPTH)
        self.pubs = {p.name: self.create_publisher(p.msg_type, p.topic, qos)
                     for p in interface.inputs if p.name in present}
        self.published = dict.fromkeys(self.pubs, 0)
        self.node_values: dict[str, str] = {}   # the node's latest diagnostic values
        diagnostics = interface.output('diagnostics')
        self.create_subscription(diagnostics.msg_type, diagnostics.topic, self._on_diagnostics, QoSProfile(depth=10))

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            self.node_values = {kv.key: kv.value for kv in status.values}

    def publish(self, stream: str, msg) -> None:
        self.pubs[stream].publish(msg)
        self.published[stream] += 1

    def node_count(self, key: str) -> int:
        try:
            return int(self.node_values.get(key, -1))
        except ValueError:
            return -1

    def node_outputs(self) -> list[str]:
        """The outputs the node says it publishes (`output.<name>_subscribers` in its diagnostics)."""
        return [k[len('output.'):-len('_subscribers')] for k in self.node_values
                if k.startswith('output.') and k.endswith('_subscribers')]


class _Recorder(Node):
    """Subscribes every output of the node and writes it to the bag."""

    def __init__(self, context: Context, writer: BagWriter, interface: NodeInterface, lock: threading.Lock):
        super().__init__('gtc_bag_recorder', context=context)
        self.sinks, self.subs = {}, {}
        for port in interface.outputs:
            sink = _BagRecorder(writer, port, lock)
            self.sinks[port.name] = sink
            self.subs[port.name] = self.create_subscription(port.msg_type, port.topic, sink.publish,
                                                            QoSProfile(depth=_LIVE_QUEUE_DEPTH))


def _outputs_matched(player: _Player, recorder: _Recorder) -> bool:
    """Every output the node publishes is matched on both sides: the node's publisher reports a
    subscription and the recorder's subscription a publisher. Outputs are volatile: what a writer
    publishes before it has matched a reader never reaches it, and the STKF node builds imu/heading
    only while it sees a subscriber."""
    names = player.node_outputs()
    return bool(names) and all(player.node_count(f'output.{n}_subscribers') > 0 and n in recorder.subs
                               and recorder.subs[n].get_publisher_count() > 0 for n in names)


# Live replay waits on conditions, never on elapsed time; these only bound a wait that would hang.
_DISCOVERY_TIMEOUT_S = 60.0
_DELIVERY_TIMEOUT_S = 180.0
_STOP_TIMEOUT_S = 180.0   # Ctrl-C to exit, hang guard only


def _replay_live(kind, reader, writer, span, total, rate, context, params_file, overrides, node_executor) -> str | None:
    """The node runs as its own process (as `ros2 run` starts it: no shared GIL with the player).

    What the node computes must not depend on timing, so the run is fenced by conditions: playing
    starts once the node reports every input matched (samples sent before a subscription matched
    would be lost) and every output matched to the recorder on both sides, the node is stopped once
    it reports every sample received, and recording ends once the recorder holds every output the
    node says it published (it waits for acknowledgements before it exits)."""
    interface = NODES[kind]
    lock = threading.Lock()
    player = _Player(context, interface, reader.streams_present())
    recorder = _Recorder(context, writer, interface, lock)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    executor.add_node(player)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    log = tempfile.TemporaryFile(mode='w+')
    node_proc = subprocess.Popen([sys.executable, '-m', f'{__package__}.{interface.executable}',
                                  '--executor', node_executor,
                                  *_ros_args(params_file, {**_LIVE_OVERRIDES, **_LIVE_NODE_OVERRIDES.get(kind, {}),
                                                           **overrides})],
                                 stderr=log, text=True)
    try:
        _wait_until(lambda: all(pub.get_subscription_count() > 0 for pub in player.pubs.values())
                    and all(player.node_count(f'input.{s}_publishers') > 0 for s in player.pubs),
                    node_proc, log, _DISCOVERY_TIMEOUT_S,
                    'the node did not match the replayed topics (DDS discovery on loopback failed?)')
        _wait_until(lambda: _outputs_matched(player, recorder), node_proc, log, _DISCOVERY_TIMEOUT_S,
                    "the recorder and the node's outputs did not match (DDS discovery on loopback failed?)")
        t0_bag, t0_wall = None, time.monotonic()
        with progress(total=total, desc=f'replay --live {kind}') as bar:
            for chunk, raw in reader.chunks(10.0, keep_raw=True):
                chunk, raw = _limit(chunk, span), _limit_raw(raw, span, reader)
                with lock:
                    writer.write_raw_records(raw)
                for t, stream, msg in _messages(chunk, player.pubs, TimeOrigin(reader.time_origin_ns)):
                    t0_bag = t if t0_bag is None else t0_bag
                    delay = t0_wall + (t - t0_bag) / rate - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    player.publish(stream, msg)
                if t0_bag is not None:
                    bar.update_to(t - t0_bag)
        _wait_until(lambda: all(player.node_count(f'input.{s}_received') >= n for s, n in player.published.items()),
                    node_proc, log, _DELIVERY_TIMEOUT_S, 'the node did not receive every replayed sample')
        _stop(node_proc, log)
        published = _published_count(log)
        sink = recorder.sinks[interface.outputs[0].name]
        _wait_until(lambda: sink.count >= published, None, log, _DELIVERY_TIMEOUT_S,
                    f'recorded {sink.count} of the {published} outputs the node published')
        said = re.findall(r'stopped: \d+ outputs published; (.*)', _node_log(log))
        return said[-1].strip() if said else None
    finally:
        _stop(node_proc)
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        player.destroy_node()
        recorder.destroy_node()
        log.close()


def _stop(node_proc, log=None) -> None:
    """Ctrl-C: the node processes what it buffered, publishes, waits for its subscribers to
    acknowledge (`stop_delivery_wait_s`), saves its state and exits. On a starved CPU that can take
    tens of seconds: the limit only turns a hang into an error, said in the log."""
    if node_proc.poll() is None:
        node_proc.send_signal(signal.SIGINT)
        try:
            node_proc.wait(timeout=_STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            node_proc.send_signal(signal.SIGUSR1)   # run_node: the stacks go to the log
            time.sleep(2.0)
            node_proc.kill()
            node_proc.wait()
            if log is not None:
                log.write(f'\n[replay: killed, still running {_STOP_TIMEOUT_S:.0f} s after Ctrl-C; stacks above]\n')


def _node_log(log) -> str:
    log.seek(0)
    return log.read()


def _published_count(log) -> int:
    """The count from the node's last log line, 'stopped: N outputs published'."""
    found = re.findall(r'stopped: (\d+) outputs published', _node_log(log))
    if not found:
        raise RuntimeError(f'the node did not stop cleanly: {_node_log(log).strip()[-8000:]}')
    return int(found[-1])


def _wait_until(condition, node_proc, log, timeout_s: float, failure: str) -> None:
    end = time.monotonic() + timeout_s
    while not condition():
        if node_proc is not None and node_proc.poll() is not None:
            raise RuntimeError(f'the node exited: {_node_log(log).strip()[-2000:]}')
        if time.monotonic() > end:
            raise RuntimeError(f'{failure} within {timeout_s:.0f} s')
        time.sleep(0.05)


def _messages(chunk: SensorChunk, inputs, origin: TimeOrigin = conv.ABSOLUTE):
    """(t, stream, rclpy message) of the input streams, in stamp order; `t` is s since `origin`."""
    items = []
    for stream in inputs:
        s = getattr(chunk, stream)
        if s is None:
            continue
        for i, t in enumerate(s.t.tolist()):
            items.append((t, stream, i))
    items.sort(key=lambda x: x[0])
    for t, stream, i in items:
        s = getattr(chunk, stream)
        header = Header(stamp=conv.time_msg(t, origin), frame_id=topics.IMU_FRAME)
        if stream in ('imu', 'imu_aux'):
            msg = conv.imu_msg(header, s.gyro[i], s.accel[i])
        elif stream == 'mag':
            msg = MagneticField(header=header)
            msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = map(float, s.field[i])
        elif stream == 'temperature':
            msg = Temperature(header=header, temperature=float(s.temp_c[i]))
        else:
            msg = JointState(header=header, name=[topics.CAROUSEL_JOINT], position=[float(s.position[i])],
                             velocity=[float(s.velocity[i])])
        yield t, stream, msg
