"""rosbag2 writing: SensorChunks, ROS messages and raw CDR records into a rosbag2 folder.

The folder is written as rosbag2 Jazzy writes it (bag_storage.py: zstd mcap chunks with CRCs,
offered QoS and type hashes), readable by rosbags, the `mcap` ROS 2 decoder, `ros2 bag` and Foxglove.
Messages are built or encoded by bag_messages.py.

Speed: Imu, MagneticField and Temperature are encoded as arrays (cdr.py), other types message by
message through rosbags; `write_raw_records` / `write_raw_many` write already serialised records in
batches, so a replay copies its inputs (`BagReader.chunks(keep_raw=True)`) without re-serialising them.

Time: a writer adds its `time_origin_ns` to the float times it is given (seconds since that origin,
stamps.py); log times and `write`/`write_raw*` stamps are integer ns since 1970.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin

from . import topics
from .bag_errors import BagError
from .bag_messages import BUILDERS, ENCODERS, Covariances, stamp_to_ns
from .bag_storage import Rosbag2Writer, offered_qos
from .cdr import TYPESTORE
from .samples import SensorChunk
from .stamps import ns_at

if TYPE_CHECKING:  # annotations only: the writer needs no reader at run time
    from .bag_reader import RawRecords


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
                   TYPESTORE.types['std_msgs/msg/String'](data=text))

    def write_chunk(self, chunk: SensorChunk) -> None:
        """Write all streams of a chunk, interleaved in stamp order (as a recorder would log them)."""
        times, conns, stamps, data = [], [], [], []
        for name, samples in chunk.streams().items():
            if name not in BUILDERS:
                raise BagError(f'no bag topic for stream {name!r}')
            topic, msgtype = topics.BAG_STREAMS[name]
            build, frame_id = BUILDERS[name]
            conns.append(self._connection(topic, msgtype))
            t_ns = ns_at(np.asarray(samples.t), self.time_origin_ns)
            if name in ENCODERS:
                data += ENCODERS[name](samples, frame_id, self.covariances, t_ns)
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

