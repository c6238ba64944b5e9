"""ROS 1 bags (`#ROSBAG V2.0`) through rosbags, streamed: sensor_msgs/Imu, MagneticField,
Temperature (and nav_msgs/Odometry truth) on the package's topic names or a `--topic` map. Messages
are decoded with the ROS 1 Noetic type store; samples are in REP 103 frames as ROS publishes them.
Times are s since the bag's first message's log time, as for ROS 2 bags."""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from .. import topics
from ..bag_io import message_row, samples_from_rows, stream_msgtypes
from ..samples import SensorChunk
from .base import Source, SourceError

MAGIC = b'#ROSBAG V2.0'


class Rosbag1Source(Source):
    kind, label = 'rosbag1', 'ROS 1 bag'

    def __init__(self, path, topic_map: dict[str, str] | None = None):
        from rosbags.rosbag1 import Reader
        from rosbags.typesys import Stores, get_typestore
        super().__init__(path)
        self.topic_map = {name: topic for name, (topic, _) in topics.BAG_STREAMS.items()}
        self.topic_map.update(topic_map or {})
        self._typestore = get_typestore(Stores.ROS1_NOETIC)
        self._reader = Reader(Path(path))
        try:
            self._reader.open()
        except Exception as exc:   # rosbags raises ReaderError and struct errors for damaged bags
            raise SourceError(f'{path}: not a readable ROS 1 bag ({type(exc).__name__}: {exc})') from None
        if not self._reader.connections:
            raise SourceError(f'ROS 1 bag {path} holds no message')
        self.time_origin_ns = int(self._reader.start_time)
        by_topic = {c.topic: c.msgtype for c in self._reader.connections}
        for name, topic in self.topic_map.items():
            if topic in by_topic and by_topic[topic] not in stream_msgtypes(name):
                raise SourceError(f'ROS 1 bag {path}: topic {topic} has type {by_topic[topic]}, expected '
                                  f'{" or ".join(sorted(stream_msgtypes(name)))}')
        self._present = {name: topic for name, topic in self.topic_map.items() if topic in by_topic
                         and self._reader.topics[topic].msgcount > 0}
        if 'imu' not in self._present:
            usable = sorted(f'{c.topic} ({c.msgtype.rsplit("/", 1)[-1]})' for c in self._reader.connections
                            if any(c.msgtype in stream_msgtypes(s) for s in ('imu', 'mag', 'temperature')))
            raise SourceError(f'ROS 1 bag {path} has no message on {self.topic_map["imu"]}; '
                              + (f'map its topics with --topic imu=/name (sensor topics: {", ".join(usable)})'
                                 if usable else 'it has no sensor_msgs/Imu topic'))

    def close(self) -> None:
        self._reader.close()

    def streams_present(self) -> dict[str, str]:
        return dict(self._present)

    def span_s(self) -> tuple[float, float]:
        lo, hi = self._window
        start = 0.0
        end = (self._reader.end_time - self.time_origin_ns) * 1e-9
        return (start if lo is None else max(start, lo)), (end if hi is None else min(end, hi))

    def rate_hz(self, stream: str) -> float | None:
        topic = self._present.get(stream)
        if topic is None:
            return None
        n = self._reader.topics[topic].msgcount
        dur = self._reader.duration * 1e-9
        return (n - 1) / dur if n > 1 and dur > 0 else None

    def _chunks(self, chunk_s: float, streams: list[str]) -> Iterator[SensorChunk]:
        topic_to_name = {self._present[s]: s for s in streams}
        conns = [c for c in self._reader.connections if c.topic in topic_to_name]
        chunk_ns = max(1, int(chunk_s * 1e9))
        rows: dict[str, list] = {s: [] for s in streams}
        current, undecodable = None, 0
        for conn, t_ns, raw in self._reader.messages(connections=conns):
            index = (t_ns - self.time_origin_ns) // chunk_ns
            if current is not None and index != current and any(rows.values()):
                yield self._chunk(rows)
                rows = {s: [] for s in streams}
            current = index
            name = topic_to_name[conn.topic]
            try:
                msg = self._typestore.deserialize_ros1(raw, conn.msgtype)
            except Exception:   # a damaged message: counted, the rest is read
                undecodable += 1
                continue
            row = message_row(name, msg, self.time_origin_ns)
            if row is not None:
                rows[name].append(row)
        if any(rows.values()):
            yield self._chunk(rows)
        if undecodable:
            self.dropped.add('bag', 'undecodable message', undecodable)

    @staticmethod
    def _chunk(rows: dict[str, list]) -> SensorChunk:
        out = {}
        for name, r in rows.items():
            if r:
                s = samples_from_rows(name, r)
                order = np.argsort(s.t, kind='stable')
                out[name] = s if np.all(order == np.arange(len(order))) else type(s)(
                    *(getattr(s, f)[order] for f in s.__dataclass_fields__))
        return SensorChunk(**out)
