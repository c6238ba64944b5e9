"""rosbag2 (mcap) reading and writing: the only module that parses or builds bag messages.

Reading streams a bag as time-ordered `SensorChunk`s, so an hours-long 1 kHz bag never sits in
memory whole. Writing turns chunks (and arbitrary ROS messages, for node outputs) into a rosbag2
folder as rosbag2 Jazzy writes it (bag_storage.py: zstd mcap chunks with CRCs, offered QoS and type
hashes), readable by rosbags, the `mcap` ROS 2 decoder, `ros2 bag` and Foxglove. Message types come
from rosbags' ROS 2 Jazzy typestore.

Speed: Imu, MagneticField and Temperature are decoded and encoded as arrays (cdr.py),
other types message by message through rosbags; `chunks(keep_raw=True)` hands out the records as
stored and `write_raw_records` / `write_raw_many` write them in batches, so a replay copies its
inputs without re-serialising them.

Time: sample times in chunks are float seconds since a time origin (stamps.py), never since 1970:
a reader's `time_origin_ns` is the log time of the bag's first message, and a writer adds its own
`time_origin_ns` to the float times it is given. Log times and `write`/`write_raw*` stamps are integer
ns since 1970.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin

from . import cdr, topics
from .bag_storage import Rosbag2Writer, offered_qos
from .cdr import TYPESTORE
from .samples import (ImuSamples, JointSamples, MagSamples, PoseSamples, SensorChunk,
                      TemperatureSamples, VectorSamples)
from .stamps import NS_PER_S, ns_at, seconds_since

_T = TYPESTORE.types
_Time, _Header = _T['builtin_interfaces/msg/Time'], _T['std_msgs/msg/Header']
_Vec3, _Quat, _Point = _T['geometry_msgs/msg/Vector3'], _T['geometry_msgs/msg/Quaternion'], _T['geometry_msgs/msg/Point']

NO_ORIENTATION_COV = np.array([-1.0] + [0.0] * 8)  # REP 145 / sensor_msgs: orientation not provided
_ZERO9, _ZERO36 = np.zeros(9), np.zeros(36)


class BagError(ValueError):
    """A bag that cannot be read or written; the message is one line meant for the user.

    Raised for: not a bag / unreadable, no readable message on the streams asked for, a known
    stream topic (topics.BAG_STREAMS, or the reader's topic_map) carrying another message type, and
    output bags that cannot be written."""


class BagWarning(UserWarning):
    """A bag that is read only in part (truncated, damaged, undecodable messages). The message is
    one line meant for the user; it is issued once per bag and message text (the default warning
    filter deduplicates it), and the CLI prints it as `gyro-thermal-comp: warning: <message>`."""


def stamp_to_ns(t_s: float, origin_ns: int = 0) -> int:
    """Seconds since `origin_ns` -> integer nanoseconds since 1970, rounded so k/rate stamps round-trip."""
    return ns_at(t_s, origin_ns)


def _header(t_ns: int, frame_id: str):
    return _Header(stamp=_Time(sec=t_ns // NS_PER_S, nanosec=t_ns % NS_PER_S), frame_id=frame_id)


def _stamp_s(header, origin_ns: int) -> float:
    return seconds_since(header.stamp.sec * NS_PER_S + header.stamp.nanosec, origin_ns)


def _diag_cov(variances) -> np.ndarray:
    """Per-axis variances -> row-major 3x3 covariance; None means unknown (all zeros, per sensor_msgs)."""
    return _ZERO9 if variances is None else np.diag(np.broadcast_to(np.asarray(variances, float), 3)).ravel()


@dataclass
class Covariances:
    """Noise variances written into raw sensor messages (None = unknown: zeros, as sensor_msgs says)."""
    gyro_rad2_s2: object = None       # per-axis variance of one gyro sample, (rad/s)^2
    accel_m2_s4: object = None        # per-axis variance of one accel sample, (m/s^2)^2
    mag_t2: object = None             # per-axis variance of one magnetometer sample, T^2
    temperature_c2: float = 0.0       # variance of one temperature reading, degC^2


# ---------------------------------------------------------------- samples -> messages
def _imu_msgs(s: ImuSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    gcov, acov = _diag_cov(cov.gyro_rad2_s2), _diag_cov(cov.accel_m2_s4)
    Imu, quat0 = _T['sensor_msgs/msg/Imu'], _Quat(x=0.0, y=0.0, z=0.0, w=1.0)
    for t_ns, g, a in zip(_ns(s.t, origin_ns), s.gyro.tolist(), s.accel.tolist()):
        yield t_ns, Imu(header=_header(t_ns, frame_id), orientation=quat0, orientation_covariance=NO_ORIENTATION_COV,
                        angular_velocity=_Vec3(x=g[0], y=g[1], z=g[2]), angular_velocity_covariance=gcov,
                        linear_acceleration=_Vec3(x=a[0], y=a[1], z=a[2]), linear_acceleration_covariance=acov)


def _mag_msgs(s: MagSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    Mag, mcov = _T['sensor_msgs/msg/MagneticField'], _diag_cov(cov.mag_t2)
    for t_ns, m in zip(_ns(s.t, origin_ns), s.field.tolist()):
        yield t_ns, Mag(header=_header(t_ns, frame_id), magnetic_field=_Vec3(x=m[0], y=m[1], z=m[2]),
                        magnetic_field_covariance=mcov)


def _temperature_msgs(s: TemperatureSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    Temp = _T['sensor_msgs/msg/Temperature']
    for t_ns, temp in zip(_ns(s.t, origin_ns), s.temp_c.tolist()):
        yield t_ns, Temp(header=_header(t_ns, frame_id), temperature=temp, variance=float(cov.temperature_c2))


def _odom_msgs(s: PoseSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    T = _T
    Odom, PwC, TwC = T['nav_msgs/msg/Odometry'], T['geometry_msgs/msg/PoseWithCovariance'], T['geometry_msgs/msg/TwistWithCovariance']
    Pose, Twist = T['geometry_msgs/msg/Pose'], T['geometry_msgs/msg/Twist']
    for t_ns, q, p, v, w in zip(_ns(s.t, origin_ns), s.quat.tolist(), s.position.tolist(),
                                s.velocity_body.tolist(), s.rate_body.tolist()):
        pose = Pose(position=_Point(x=p[0], y=p[1], z=p[2]), orientation=_Quat(x=q[0], y=q[1], z=q[2], w=q[3]))
        twist = Twist(linear=_Vec3(x=v[0], y=v[1], z=v[2]), angular=_Vec3(x=w[0], y=w[1], z=w[2]))
        yield t_ns, Odom(header=_header(t_ns, topics.ODOM_FRAME), child_frame_id=topics.BODY_FRAME,
                         pose=PwC(pose=pose, covariance=_ZERO36), twist=TwC(twist=twist, covariance=_ZERO36))


def _vector_msgs(s: VectorSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    V3S = _T['geometry_msgs/msg/Vector3Stamped']
    for t_ns, v in zip(_ns(s.t, origin_ns), s.vec.tolist()):
        yield t_ns, V3S(header=_header(t_ns, frame_id), vector=_Vec3(x=v[0], y=v[1], z=v[2]))


def _joint_msgs(s: JointSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    JS, empty = _T['sensor_msgs/msg/JointState'], np.zeros(0)
    for t_ns, pos, vel in zip(_ns(s.t, origin_ns), s.position.tolist(), s.velocity.tolist()):
        yield t_ns, JS(header=_header(t_ns, frame_id), name=[topics.CAROUSEL_JOINT],
                       position=np.array([pos]), velocity=np.array([vel]), effort=empty)


def _ns(t_s: np.ndarray, origin_ns: int) -> list[int]:
    return ns_at(np.asarray(t_s), origin_ns).tolist()


# Fixed-layout streams are encoded in bulk (cdr.py): the same bytes as the builders above would give.
def _imu_cdr(s: ImuSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_imu(t_ns, frame_id, orientation_covariance=NO_ORIENTATION_COV, angular_velocity=s.gyro,
                          angular_velocity_covariance=_diag_cov(cov.gyro_rad2_s2), linear_acceleration=s.accel,
                          linear_acceleration_covariance=_diag_cov(cov.accel_m2_s4))


def _mag_cdr(s: MagSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_mag(t_ns, frame_id, s.field, _diag_cov(cov.mag_t2))


def _temperature_cdr(s: TemperatureSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_temperature(t_ns, frame_id, s.temp_c, float(cov.temperature_c2))


_ENCODERS = {'imu': _imu_cdr, 'imu_aux': _imu_cdr, 'mag': _mag_cdr, 'temperature': _temperature_cdr}


# SensorChunk field -> (message builder, frame id)
_BUILDERS = {
    'imu': (_imu_msgs, topics.IMU_FRAME),
    'imu_aux': (_imu_msgs, topics.IMU_FRAME + '_aux'),
    'mag': (_mag_msgs, topics.IMU_FRAME),
    'temperature': (_temperature_msgs, topics.IMU_FRAME),
    'odom': (_odom_msgs, topics.ODOM_FRAME),
    'gyro_bias': (_vector_msgs, topics.IMU_FRAME),
    'mag_disturbance': (_vector_msgs, topics.IMU_FRAME),
    'joint': (_joint_msgs, topics.BODY_FRAME),
}


class BagWriter:
    """Writes a rosbag2 folder (mcap storage, zstd chunks). Use as a context manager.

    `write_chunk` writes every stream of a SensorChunk under its standard topic, merged in stamp
    order; `write` adds any ROS message (node outputs). Log time = header stamp. Each topic offers
    `bag_storage.offered_qos(topic)`.

    Float times (`write_chunk`, `write_text`) are seconds since `time_origin_ns` (ns since 1970;
    set it before writing: the simulator's `sim.EPOCH_NS`, or a reader's `time_origin_ns` to
    write what it read at the stamps it had). `write` and `write_raw` take ns since 1970.

    The bag is written into a temporary sibling folder (`.NAME.*.partial`) and renamed to `path`
    only when the `with` block ends without an exception; otherwise the temporary folder is removed
    and nothing appears under `path`. `overwrite=True` replaces an existing `path` at that moment
    (a failed run leaves it as it was); without it an existing `path` is an error up front.
    """

    def __init__(self, path, *, overwrite: bool = False, covariances: Covariances | None = None,
                 time_origin_ns: int = 0):
        self.path = Path(path)
        self.overwrite = overwrite
        self.covariances = covariances or Covariances()
        self.time_origin_ns = int(time_origin_ns)
        if self.path.exists() and not overwrite:
            raise BagError(f'output bag {self.path} already exists (use --force to overwrite)')
        if not self.path.parent.is_dir():
            raise BagError(f'cannot write bag {self.path}: folder {self.path.parent} does not exist')
        self._tmp: Path | None = None
        self._writer = None
        self._connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}

    def __enter__(self) -> 'BagWriter':
        try:
            self._tmp = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.', suffix='.partial',
                                              dir=self.path.parent))
        except OSError as exc:
            raise BagError(f'cannot write bag {self.path}: {exc.strerror or exc}') from None
        try:  # the mcap file takes the folder's name: write it under the final name inside the temp folder
            self._writer = Rosbag2Writer(self._tmp / self.path.name, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            self._writer.open()
        except Exception as exc:  # rosbags raises its own WriterError for paths
            self._discard()
            raise BagError(f'cannot write bag {self.path}: {exc}') from None
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self._discard()
            return False
        try:
            self._writer.close()
        except Exception as close_exc:
            self._discard()
            raise BagError(f'cannot write bag {self.path}: {close_exc}') from None
        self._commit()
        return False

    def _commit(self) -> None:
        """Move the finished bag from its temporary folder to `path`."""
        try:
            if self.path.is_dir() and not self.path.is_symlink():
                if not self.overwrite:
                    raise BagError(f'output bag {self.path} already exists (use --force to overwrite)')
                shutil.rmtree(self.path)
            elif self.path.exists() or self.path.is_symlink():
                if not self.overwrite:
                    raise BagError(f'output bag {self.path} already exists (use --force to overwrite)')
                self.path.unlink()
            os.replace(self._tmp / self.path.name, self.path)
        except OSError as exc:
            self._discard()
            raise BagError(f'cannot write bag {self.path}: {exc}') from None
        except BagError:
            self._discard()
            raise
        self._tmp.rmdir()
        self._tmp = None

    def _discard(self) -> None:
        """Close what is open and remove the temporary folder: nothing is left behind."""
        if self._writer is not None:
            try:
                self._writer.close()
            except Exception:  # noqa: S110 (already failing; the folder goes anyway)
                pass
            self._writer = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def _connection(self, topic: str, msgtype: str):
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._writer.add_connection(topic, msgtype, typestore=TYPESTORE,
                                               offered_qos_profiles=[offered_qos(topic)])
            self._connections[topic] = conn
            self.counts[topic] = 0
        elif conn.msgtype != msgtype:
            raise BagError(f'topic {topic} already has type {conn.msgtype}, not {msgtype}')
        return conn

    def write(self, topic: str, msgtype: str, t_ns: int, msg) -> None:
        """Write one ROS message (a rosbags typestore object) at log time t_ns."""
        conn = self._connection(topic, msgtype)
        self._writer.write(conn, t_ns, TYPESTORE.serialize_cdr(msg, msgtype))
        self.counts[topic] += 1

    def write_raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """Write an already CDR-serialised message (e.g. rclpy's serialize_message output)."""
        self._writer.write(self._connection(topic, msgtype), t_ns, data)
        self.counts[topic] += 1

    def write_raw_many(self, topic: str, msgtype: str, t_ns, data: Sequence[bytes]) -> None:
        """Write many CDR messages of one topic at once (e.g. cdr.encode_imu output), in the order
        given; `t_ns`: (n,) log times, integer ns since 1970."""
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if t_ns.shape != (len(data),):
            raise ValueError(f'{t_ns.shape} log times for {len(data)} messages')
        self._write_ordered([self._connection(topic, msgtype)], np.zeros(len(data), np.int64), t_ns, data)

    def write_raw_records(self, records: 'RawRecords') -> None:
        """Write records read by `BagReader.chunks(keep_raw=True)` unchanged (bytes and log times),
        in their order: copying a bag's messages without deserialising or re-serialising them."""
        keys = list(zip(records.topic.tolist(), records.msgtype.tolist()))
        unique = list(dict.fromkeys(keys))
        index = {k: i for i, k in enumerate(unique)}
        self._write_ordered([self._connection(t, m) for t, m in unique],
                            np.fromiter((index[k] for k in keys), np.int64, len(keys)), records.log_time_ns,
                            records.data)

    def _write_ordered(self, conns: list, which: np.ndarray, t_ns: np.ndarray, data: Sequence[bytes]) -> None:
        """Record k: `data[k]` on `conns[which[k]]` at log time `t_ns[k]`."""
        self._writer.write_many(conns, which.tolist(), np.asarray(t_ns, np.int64).tolist(), data)
        for conn, n in zip(conns, np.bincount(which, minlength=len(conns)).tolist()):
            self.counts[conn.topic] += n

    def write_text(self, topic: str, t_s: float, text: str) -> None:
        """A std_msgs/String at `t_s`, seconds since time_origin_ns."""
        self.write(topic, 'std_msgs/msg/String', stamp_to_ns(t_s, self.time_origin_ns),
                   _T['std_msgs/msg/String'](data=text))

    def write_chunk(self, chunk: SensorChunk) -> None:
        """Write all streams of a chunk, interleaved in stamp order (as a recorder would log them)."""
        times, conns, stamps, data = [], [], [], []
        for name, samples in chunk.streams().items():
            if name not in _BUILDERS:
                raise BagError(f'no bag topic for stream {name!r}')
            topic, msgtype = topics.BAG_STREAMS[name]
            build, frame_id = _BUILDERS[name]
            conns.append(self._connection(topic, msgtype))
            t_ns = ns_at(np.asarray(samples.t), self.time_origin_ns)
            if name in _ENCODERS:
                data += _ENCODERS[name](samples, frame_id, self.covariances, t_ns)
            else:
                data += [TYPESTORE.serialize_cdr(msg, msgtype)
                         for _, msg in build(samples, frame_id, self.covariances, self.time_origin_ns)]
            times.append(samples.t)
            stamps.append(t_ns)
        if not times:
            return
        which = np.concatenate([np.full(len(t), i) for i, t in enumerate(times)])
        order = np.argsort(np.concatenate(times), kind='stable')
        self._write_ordered(conns, which[order], np.concatenate(stamps)[order], [data[i] for i in order.tolist()])


# ---------------------------------------------------------------- messages -> samples
def _imu_row(msg, origin_ns: int):
    g, a = msg.angular_velocity, msg.linear_acceleration
    return _stamp_s(msg.header, origin_ns), g.x, g.y, g.z, a.x, a.y, a.z


def _mag_row(msg, origin_ns: int):
    m = msg.magnetic_field
    return _stamp_s(msg.header, origin_ns), m.x, m.y, m.z


def _temperature_row(msg, origin_ns: int):
    return _stamp_s(msg.header, origin_ns), msg.temperature


def _odom_row(msg, origin_ns: int):
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    return _stamp_s(msg.header, origin_ns), q.x, q.y, q.z, q.w, p.x, p.y, p.z, v.x, v.y, v.z, w.x, w.y, w.z


def _vector_row(msg, origin_ns: int):
    v = msg.vector
    return _stamp_s(msg.header, origin_ns), v.x, v.y, v.z


def _joint_row(msg, origin_ns: int):
    if len(msg.position) == 0:
        return None
    vel = msg.velocity[0] if len(msg.velocity) else math.nan
    return _stamp_s(msg.header, origin_ns), msg.position[0], vel


def _to_imu(a): return ImuSamples(a[:, 0], a[:, 1:4], a[:, 4:7])
def _to_mag(a): return MagSamples(a[:, 0], a[:, 1:4])
def _to_temperature(a): return TemperatureSamples(a[:, 0], a[:, 1])
def _to_odom(a): return PoseSamples(a[:, 0], a[:, 1:5], a[:, 5:8], a[:, 8:11], a[:, 11:14])
def _to_vector(a): return VectorSamples(a[:, 0], a[:, 1:4])
def _to_joint(a): return JointSamples(a[:, 0], a[:, 1], a[:, 2])


# stream -> (row extractor, accepted message types, row width, array -> samples)
_READERS = {
    'imu': (_imu_row, {'sensor_msgs/msg/Imu'}, 7, _to_imu),
    'imu_aux': (_imu_row, {'sensor_msgs/msg/Imu'}, 7, _to_imu),
    'mag': (_mag_row, {'sensor_msgs/msg/MagneticField'}, 4, _to_mag),
    'temperature': (_temperature_row, {'sensor_msgs/msg/Temperature'}, 2, _to_temperature),
    'odom': (_odom_row, {'nav_msgs/msg/Odometry'}, 14, _to_odom),
    'gyro_bias': (_vector_row, {'geometry_msgs/msg/Vector3Stamped'}, 4, _to_vector),
    'mag_disturbance': (_vector_row, {'geometry_msgs/msg/Vector3Stamped'}, 4, _to_vector),
    'joint': (_joint_row, {'sensor_msgs/msg/JointState'}, 3, _to_joint),
}


def stream_msgtypes(stream: str) -> set[str]:
    """The ROS message types a stream is read from (ROS 1 and ROS 2 name them alike in rosbags)."""
    return set(_READERS[stream][1])


def message_row(stream: str, msg, origin_ns: int):
    """One decoded message of `stream` as a row [t, values...] (t in s since origin_ns), or None for
    a message without a value (a JointState with no position): for readers of other bag formats."""
    return _READERS[stream][0](msg, origin_ns)


def samples_from_rows(stream: str, rows) -> object:
    """Rows of `message_row` -> the stream's samples (ImuSamples, MagSamples, ...)."""
    return _READERS[stream][3](np.asarray(rows, np.float64).reshape(-1, _READERS[stream][2]))


# stream -> (fixed-layout type decoded in bulk by cdr.decode, its fields after the stamp, as _READERS' rows)
_FAST = {
    'imu': (cdr.IMU, ('angular_velocity', 'linear_acceleration')),
    'imu_aux': (cdr.IMU, ('angular_velocity', 'linear_acceleration')),
    'mag': (cdr.MAG, ('magnetic_field',)),
    'temperature': (cdr.TEMPERATURE, ('temperature',)),
}


@dataclass(frozen=True)
class TopicInfo:
    topic: str
    msgtype: str
    count: int
    offered_qos: tuple = ()   # rosbags Qos profiles from the metadata (intact bags)
    type_hash: str = ''       # RIHS01_... (intact bags)


class _Rosbag2Source:
    """An intact rosbag2 folder, read through rosbags (uses the mcap summary: fast, indexed)."""

    def __init__(self, path: Path):
        self._reader = Reader(path)
        self._reader.open()

    def topics(self) -> list[TopicInfo]:
        return [TopicInfo(c.topic, c.msgtype, c.msgcount, tuple(getattr(c.ext, 'offered_qos_profiles', ())),
                          c.digest) for c in self._reader.connections]

    def span_ns(self) -> tuple[int, int]:
        return self._reader.start_time, self._reader.end_time

    def raw(self, wanted: set[str] | None):
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None and not conns:   # rosbags reads an empty connection list as "all"
            return
        for conn, t_ns, raw in self._reader.messages(connections=conns):
            yield conn.topic, conn.msgtype, t_ns, raw

    def close(self):
        self._reader.close()


class _McapStreamSource:
    """A damaged or unfinished mcap file (no footer or summary, e.g. a recorder that was killed):
    records are streamed from the start and reading stops cleanly at the first broken one."""

    def __init__(self, mcap_file: Path):
        from mcap.stream_reader import StreamReader  # noqa: F401  (fail early if mcap is missing)
        self._file = mcap_file
        self._scan = None
        self.stopped_by: Exception | None = None   # what ended the counting pass early

    def _records(self):
        from mcap.records import Channel, Message, Schema
        from mcap.stream_reader import StreamReader
        schemas, channels = {}, {}
        with open(self._file, 'rb') as fh:
            for record in StreamReader(fh).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ''))
                elif isinstance(record, Message) and record.channel_id in channels:
                    topic, msgtype = channels[record.channel_id]
                    yield topic, msgtype, record.log_time, record.data

    def _scan_once(self):
        if self._scan is None:  # one counting pass for topics() and span_ns()
            counts, types, lo, hi = {}, {}, None, None
            try:
                for topic, msgtype, t_ns, _ in self._records():
                    counts[topic] = counts.get(topic, 0) + 1
                    types[topic] = msgtype
                    lo, hi = (t_ns, t_ns) if lo is None else (min(lo, t_ns), max(hi, t_ns))
            except Exception as exc:  # the broken tail: raw() reports it when the data is actually read
                self.stopped_by = exc
            self._scan = ([TopicInfo(t, types[t], n) for t, n in counts.items()], (lo or 0, hi or 0))
        return self._scan

    def why_empty(self) -> str:
        """Why the scan found no message, in a few words (for the error message)."""
        size = self._file.stat().st_size
        exc = self.stopped_by
        if size == 0:
            return f'{self._file.name} is empty (0 bytes)'
        if exc is None:
            return f'{self._file.name} holds no message'
        if type(exc).__name__ == 'EndOfFile':
            return f'{self._file.name} ({size} bytes) ends before its first complete message'
        return f'{self._file.name} is not a readable MCAP file ({type(exc).__name__}: {exc})'

    def topics(self) -> list[TopicInfo]:
        return self._scan_once()[0]

    def span_ns(self) -> tuple[int, int]:
        return self._scan_once()[1]

    def raw(self, wanted: set[str] | None):
        for item in self._records():
            if wanted is None or item[0] in wanted:
                yield item

    def close(self):
        pass


def _find_mcap(path: Path) -> Path | None:
    if path.is_file() and path.suffix == '.mcap':
        return path
    files = sorted(path.glob('*.mcap')) if path.is_dir() else []
    return files[0] if len(files) == 1 else None


class BagReader:
    """Reads a rosbag2 folder (or a bare .mcap file) as a stream of SensorChunks; a context manager.

    `topic_map` overrides which bag topic feeds which stream, e.g. {'imu': '/vectornav/imu'}.
    Sample times are s since `time_origin_ns` (stamps.py): full precision whatever the epoch.
    A truncated or unfinished bag yields what could be read, sets `truncated` and warns once.
    """

    def __init__(self, path, topic_map: dict[str, str] | None = None):
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'bag {self.path} does not exist')
        self.topic_map = {name: topic for name, (topic, _) in topics.BAG_STREAMS.items()}
        unknown = set(topic_map or {}) - set(_READERS)
        if unknown:
            raise BagError(f'unknown stream(s) {sorted(unknown)}; known: {sorted(_READERS)}')
        self.topic_map.update(topic_map or {})
        self.truncated = False
        self.undecodable = 0  # messages dropped because they could not be decoded
        self.time_origin_ns = 0  # set on open: log time of the first message, ns since 1970
        self._source = None

    def __enter__(self) -> 'BagReader':
        intact_error = None
        if (self.path / 'metadata.yaml').is_file():
            try:
                self._source = _Rosbag2Source(self.path)
            except Exception as exc:  # rosbags raises several types for damaged bags
                intact_error = exc
            else:
                self._check_usable()
                self.time_origin_ns = int(self._source.span_ns()[0])
                return self
        mcap_file = _find_mcap(self.path)
        if mcap_file is None:
            reason = intact_error or 'no metadata.yaml and no single .mcap file'
            raise BagError(f'cannot open bag {self.path}: {reason}')
        self._source = _McapStreamSource(mcap_file)
        self._check_usable()  # an unusable file is an error, not a warning followed by an error
        self.time_origin_ns = int(self._source.span_ns()[0])
        self._warn_truncated(f'no intact index ({_one_line(intact_error) or "no metadata.yaml"}); '
                             'streaming what is there')
        return self

    def __exit__(self, *exc):
        if self._source is not None:
            self._source.close()
        return False

    def _check_usable(self) -> None:
        """BagError unless the bag holds at least one message and every known stream topic has the
        type that stream is read as."""
        infos = self.topics
        if not any(info.count > 0 for info in infos):
            why = self._source.why_empty() if isinstance(self._source, _McapStreamSource) else 'no messages'
            self._source.close()
            raise BagError(f'bag {self.path} holds no readable message: {why}')
        by_topic = {topic: name for name, topic in self.topic_map.items()}
        for info in infos:
            name = by_topic.get(info.topic)
            if name is not None and info.msgtype not in _READERS[name][1]:
                self._source.close()
                expected = ' or '.join(sorted(_READERS[name][1]))
                raise BagError(f'bag {self.path}: topic {info.topic} has type {info.msgtype}, '
                               f'expected {expected}')

    def _warn_truncated(self, why: str) -> None:
        if not self.truncated:
            self.truncated = True
            warnings.warn(f'bag {self.path} is truncated or damaged: {why}', BagWarning, stacklevel=1)

    @property
    def topics(self) -> list[TopicInfo]:
        return self._source.topics()

    @property
    def duration_s(self) -> float:
        lo, hi = self._source.span_ns()
        return (hi - lo) * 1e-9

    @property
    def start_time_s(self) -> float:
        """Log time of the first message in the times chunks are in (s since time_origin_ns): 0."""
        return (self._source.span_ns()[0] - self.time_origin_ns) * 1e-9

    def stamp_s(self, header) -> float:
        """A message's header stamp in s since time_origin_ns (as chunks carry stamps)."""
        return _stamp_s(header, self.time_origin_ns)

    def streams_present(self) -> dict[str, str]:
        """Stream name -> bag topic, for the streams this bag actually holds (at least one message)."""
        by_topic = {info.topic: info.msgtype for info in self.topics if info.count > 0}
        return {name: topic for name, topic in self.topic_map.items()
                if by_topic.get(topic) in _READERS[name][1]}

    def _topic_hint(self) -> str:
        """'; map its topics with --topic ...' naming the topics of a type the package reads that
        no stream is mapped to ('' if there are none)."""
        mapped = set(self.topic_map.values())
        readable = set().union(*(types for _, types, _, _ in _READERS.values()))
        others = sorted(f'{t.topic} ({t.msgtype.rsplit("/", 1)[-1]})' for t in self.topics
                        if t.count > 0 and t.topic not in mapped and t.msgtype in readable)
        return f'; map its topics with --topic STREAM=/name (it has {", ".join(others)})' if others else ''

    def require(self, *streams: str) -> dict[str, str]:
        """streams_present(), or BagError naming the topics of `streams` the bag has no message on."""
        present = self.streams_present()
        missing = [self.topic_map[name] for name in streams if name not in present]
        if missing:
            raise BagError(f'bag {self.path} has no message on {", ".join(missing)}{self._topic_hint()}')
        return present

    def _records(self, wanted: set[str] | None) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, msgtype, log time ns, CDR bytes) in stored order; a bag cut off mid-record ends
        the iteration with one warning."""
        source = self._source.raw(wanted)
        while True:
            try:
                yield next(source)
            except StopIteration:
                return
            except Exception as exc:  # cut off mid-record: keep what was read, say so once
                self._warn_truncated(f'{_one_line(exc)}; stopped reading there')
                return

    def _undecodable(self, topic: str, msgtype: str, exc: Exception) -> None:
        """One corrupt or foreign message: counted, and the first one warned about."""
        self.undecodable += 1
        if self.undecodable == 1:
            warnings.warn(f'bag {self.path}: cannot decode a {msgtype} message on {topic} '
                          f'({type(exc).__name__}); dropping such messages', BagWarning, stacklevel=1)

    def messages(self, topics_: Iterable[str] | None = None) -> Iterator[tuple[str, str, int, object]]:
        """Raw access: (topic, msgtype, log time ns, deserialized message) in stored order."""
        for topic, msgtype, t_ns, raw in self._records(None if topics_ is None else set(topics_)):
            try:
                msg = TYPESTORE.deserialize_cdr(raw, msgtype)
            except Exception as exc:
                self._undecodable(topic, msgtype, exc)
                continue
            yield topic, msgtype, t_ns, msg

    def text(self, topic: str) -> list[str]:
        """All std_msgs/String payloads on a topic (e.g. /sim/config)."""
        return [m.data for _, msgtype, _, m in self.messages([topic]) if msgtype == 'std_msgs/msg/String']

    def chunks(self, chunk_s: float = 60.0, streams: Iterable[str] | None = None,
               keep_raw: bool = False) -> Iterator[SensorChunk] | Iterator[tuple[SensorChunk, 'RawRecords']]:
        """Time-ordered SensorChunks of about `chunk_s` of log time each (streams default: all present),
        sample times in s since `time_origin_ns`.

        `keep_raw=True` yields (chunk, RawRecords): with each chunk, the records it was decoded from,
        bytes untouched, in stored order (undecodable ones left out, as from the chunk), for
        `BagWriter.write_raw_records` to copy them without re-serialising.

        BagError (after the last chunk) if not one message of those streams could be read: a bag
        whose index promises data that is not there."""
        present = self.streams_present()
        names = list(present) if streams is None else [s for s in streams if s in present]
        if not names:
            if streams is None:
                raise BagError(f'bag {self.path} has no message on any topic this package reads '
                               f'({", ".join(self.topic_map.values())}){self._topic_hint()}')
            raise BagError(f'bag {self.path} has no message on '
                           f'{", ".join(self.topic_map.get(s, s) for s in streams)}{self._topic_hint()}')
        topic_to_name = {present[n]: n for n in names}
        chunk_ns, t0_ns, current = max(1, int(chunk_s * 1e9)), None, 0
        pending: list[tuple] = []       # records of the current chunk not decoded yet
        built = _ChunkParts(names, keep_raw)
        yielded = False
        for record in self._records(set(topic_to_name)):
            t_ns = record[2]
            if t0_ns is None:
                t0_ns = t_ns
            index = (t_ns - t0_ns) // chunk_ns
            if index != current:        # decode at a boundary; a chunk with no decodable sample grows on
                built.add(*self._decode(pending, topic_to_name))
                pending = []
                if built.has_rows():
                    yielded = True
                    yield built.take()
            current = index
            pending.append(record)
        built.add(*self._decode(pending, topic_to_name))
        if built.has_rows():
            yield built.take()
        elif not yielded:
            raise BagError(f'bag {self.path} holds no readable message on {", ".join(topic_to_name)}')

    def _decode(self, records: list[tuple], topic_to_name: dict[str, str]):
        """Records -> per stream (record positions, rows [t, values...]) and the positions and
        stamps (s since time_origin_ns) of every record that decoded. Imu, MagneticField and
        Temperature go through cdr.decode (arrays); other types through rosbags, one by one."""
        groups: dict[tuple[str, str], list[int]] = {}
        for k, (topic, msgtype, _, _) in enumerate(records):
            groups.setdefault((topic, msgtype), []).append(k)
        rows, ok_pos, ok_t = {}, [], []
        for (topic, msgtype), pos in groups.items():
            name = topic_to_name[topic]
            pos = np.asarray(pos, np.int64)
            fast = _FAST.get(name)
            if fast is not None and fast[0] == msgtype:
                decoded = cdr.decode([records[k][3] for k in pos.tolist()], msgtype)
                for i, exc in decoded.errors:
                    self._undecodable(topic, msgtype, exc)
                t = _seconds_since(decoded.stamp_ns, self.time_origin_ns)
                rows.setdefault(name, []).append(
                    (pos[decoded.index], np.column_stack([t, *(decoded.fields[f] for f in fast[1])])))
                ok_pos.append(pos[decoded.index])
                ok_t.append(t)
                continue
            extract, width = _READERS[name][0], _READERS[name][2]
            good, good_t, kept, kept_rows = [], [], [], []
            for k in pos.tolist():
                try:
                    msg = TYPESTORE.deserialize_cdr(records[k][3], msgtype)
                except Exception as exc:
                    self._undecodable(topic, msgtype, exc)
                    continue
                row = extract(msg, self.time_origin_ns)
                good.append(k)
                good_t.append(_stamp_s(msg.header, self.time_origin_ns) if row is None else row[0])
                if row is not None:
                    kept.append(k)
                    kept_rows.append(row)
            rows.setdefault(name, []).append((np.asarray(kept, np.int64),
                                              np.asarray(kept_rows, np.float64).reshape(-1, width)))
            ok_pos.append(np.asarray(good, np.int64))
            ok_t.append(np.asarray(good_t, np.float64))
        return records, rows, ok_pos, ok_t


class _ChunkParts:
    """What BagReader.chunks has decoded for the chunk being built."""

    def __init__(self, names: list[str], keep_raw: bool):
        self.names, self.keep_raw = names, keep_raw
        self.rows: dict[str, list[np.ndarray]] = {n: [] for n in names}
        self.raw: list[tuple] = []

    def add(self, records, rows, ok_pos, ok_t) -> None:
        for name, parts in rows.items():   # one part per message type of the stream: back in stored order
            pos = np.concatenate([p for p, _ in parts])
            block = np.concatenate([r for _, r in parts]) if len(parts) > 1 else parts[0][1]
            self.rows[name].append(block if len(parts) == 1 else block[np.argsort(pos, kind='stable')])
        if self.keep_raw and records:
            pos, t = np.concatenate(ok_pos or [np.zeros(0, np.int64)]), np.concatenate(ok_t or [np.zeros(0)])
            order = np.argsort(pos, kind='stable')
            self.raw.append(RawRecords.of([records[k] for k in pos[order].tolist()], t[order]))

    def has_rows(self) -> bool:
        return any(len(block) for blocks in self.rows.values() for block in blocks)

    def take(self):
        streams = {}
        for name, blocks in self.rows.items():
            block = np.concatenate(blocks) if len(blocks) > 1 else (blocks[0] if blocks else None)
            if block is not None and len(block):
                streams[name] = _READERS[name][3](block)
        chunk = SensorChunk(**streams)
        raw = RawRecords.join(self.raw)
        self.rows, self.raw = {n: [] for n in self.names}, []
        return (chunk, raw) if self.keep_raw else chunk


@dataclass(frozen=True)
class RawRecords:
    """Bag records as stored (CDR bytes untouched), in stored order: what a chunk was decoded from."""
    topic: np.ndarray         # (n,) object: topic of each record
    msgtype: np.ndarray       # (n,) object: its message type, e.g. 'sensor_msgs/msg/Imu'
    log_time_ns: np.ndarray   # (n,) int64: log time, ns since 1970
    stamp_s: np.ndarray       # (n,) float64: header stamp, s since the reader's time_origin_ns
    data: list                # (n,) CDR bytes

    def __len__(self) -> int:
        return len(self.data)

    @staticmethod
    def of(records: list[tuple], stamp_s: np.ndarray) -> 'RawRecords':
        n = len(records)
        topic, msgtype = np.empty(n, object), np.empty(n, object)
        topic[:] = [r[0] for r in records]
        msgtype[:] = [r[1] for r in records]
        return RawRecords(topic, msgtype, np.fromiter((r[2] for r in records), np.int64, n),
                          np.asarray(stamp_s, np.float64), [r[3] for r in records])

    @staticmethod
    def join(parts: list['RawRecords']) -> 'RawRecords':
        if len(parts) == 1:
            return parts[0]
        if not parts:
            return RawRecords.of([], np.zeros(0))
        return RawRecords(*(np.concatenate([getattr(p, f) for p in parts])
                            for f in ('topic', 'msgtype', 'log_time_ns', 'stamp_s')),
                          [d for p in parts for d in p.data])

    def renamed(self, names: dict[str, str]) -> 'RawRecords':
        """The same records with their topics renamed (old -> new; others as they are)."""
        if not names:
            return self
        topic = np.empty(len(self.topic), object)
        topic[:] = [names.get(t, t) for t in self.topic.tolist()]
        return RawRecords(topic, self.msgtype, self.log_time_ns, self.stamp_s, self.data)

    def select(self, mask) -> 'RawRecords':
        """The records where `mask` (bool, or indices) holds, e.g. `r.select(r.stamp_s < t_end)`."""
        idx = np.flatnonzero(mask) if np.asarray(mask).dtype == bool else np.asarray(mask, np.int64)
        return RawRecords(self.topic[idx], self.msgtype[idx], self.log_time_ns[idx], self.stamp_s[idx],
                          [self.data[i] for i in idx.tolist()])


def _seconds_since(stamp_ns: np.ndarray, origin_ns: int) -> np.ndarray:
    """stamps.seconds_since over an array, float for float the same (whole seconds + fraction)."""
    sec, nanosec = np.divmod(np.asarray(stamp_ns, np.int64) - np.int64(origin_ns), NS_PER_S)
    return sec.astype(np.float64) + nanosec.astype(np.float64) * 1e-9


def _one_line(exc) -> str:
    """An exception (or None) as a short single line: 'Type: message'."""
    if exc is None:
        return ''
    text = ' '.join(str(exc).split())
    return f'{type(exc).__name__}: {text}' if text else type(exc).__name__


def read_chunks(path, chunk_s: float = 60.0, streams=None, topic_map=None) -> Iterator[SensorChunk]:
    """Convenience generator: open, stream chunks, close."""
    with BagReader(path, topic_map) as reader:
        yield from reader.chunks(chunk_s, streams)
