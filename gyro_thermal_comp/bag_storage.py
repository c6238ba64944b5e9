"""The rosbag2 folder as rosbag2 Jazzy (`ros2 bag record -s mcap`) writes it, built on rosbags.

rosbags writes the metadata.yaml (version 9: offered QoS profiles as YAML lists, type description
hashes) but its mcap storage writes chunk CRCs of 0 and no `topic_type_hash` in the channel metadata.
`Rosbag2Writer` is rosbags' Writer with the mcap storage replaced by one built on the `mcap` library
that writes what rosbag2_storage_mcap writes: profile `ros2`, zstd chunks with CRCs (readers such as
rosbags and `mcap` validate them), a summary CRC, channel metadata `offered_qos_profiles` and
`topic_type_hash`, the `rosbag2` metadata record. A data section CRC is written too (rosbag2 leaves
it 0), so a stream reader can validate the whole file.

`offered_qos(topic)` is the QoS the recorded publisher offered, as rosbag2 records it from discovery.

The mcap file itself is written by `McapFile`: the same bytes as `mcap.writer.Writer` with these
settings (1 MiB zstd chunks, CRCs, all indexes, statistics, summary offsets), but messages are added
in batches, their record headers and the message indexes built with numpy: the `mcap` Writer spends
about 3 us of Python per message, which is most of a replay's bag-writing time at 1 kHz.
"""
from __future__ import annotations

import struct
import zlib
from collections import Counter
from importlib.metadata import version

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata, MetadataIndex, Schema,
                          Statistics, SummaryOffset)
from mcap.writer import LIBRARY_IDENTIFIER, MCAP0_MAGIC
from rosbags.interfaces import (MessageDefinitionFormat, Qos, QosDurability, QosHistory, QosLiveliness,
                                QosReliability, QosTime)
from rosbags.rosbag2 import CompressionMode, StoragePlugin, Writer, WriterError

from . import topics

# rosbag2 records the offered QoS from DDS discovery, which carries neither history nor depth;
# unset durations are RMW_DURATION_INFINITE.
_INFINITE = QosTime(9223372036, 854775807)


def _offered(reliability: QosReliability, durability: QosDurability = QosDurability.VOLATILE) -> Qos:
    return Qos(QosHistory.UNKNOWN, 0, reliability, durability, _INFINITE, _INFINITE,
               QosLiveliness.AUTOMATIC, _INFINITE, False)


SENSOR_DATA = _offered(QosReliability.BEST_EFFORT)      # drivers: rclpy's qos_profile_sensor_data
RELIABLE = _offered(QosReliability.RELIABLE)            # node outputs, diagnostics, ground truth
LATCHED = _offered(QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)   # published once

_SENSOR_STREAMS = ('imu', 'imu_aux', 'mag', 'temperature', 'joint')
_OFFERED = {**{topics.BAG_STREAMS[s][0]: SENSOR_DATA for s in _SENSOR_STREAMS}, topics.SIM_CONFIG: LATCHED}


def offered_qos(topic: str) -> Qos:
    """The QoS a publisher of `topic` offers: sensor data (best effort) for the raw sensor topics,
    reliable + transient local for /sim/config (sent once), reliable for everything else."""
    return _OFFERED.get(topic, RELIABLE)


# An mcap Message record before its data: opcode, record length, channel, sequence, log and publish time
_MESSAGE_HEAD = np.dtype([('op', 'u1'), ('length', '<u8'), ('channel', '<u2'), ('sequence', '<u4'),
                          ('log_time', '<u8'), ('publish_time', '<u8')])
_INDEX_ENTRY = np.dtype([('log_time', '<u8'), ('offset', '<u8')])


class McapFile:
    """A chunked mcap file, written as `mcap.writer.Writer(stream, chunk_size, ZSTD, enable_crcs=True,
    enable_data_crcs=True)` writes it (same calls, same bytes: test_bag_io checks), with
    `add_messages` for batches. Chunks close when their data passes `chunk_size`, as there."""

    def __init__(self, stream, chunk_size: int = 1 << 20):
        self._stream, self._chunk_size = stream, chunk_size
        self._out = RecordBuilder()      # records outside chunks, until flushed to the stream
        self._crc = 0                    # data section CRC
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._stats = Statistics(attachment_count=0, channel_count=0, channel_message_counts={}, chunk_count=0,
                                 message_count=0, metadata_count=0, message_start_time=0, message_end_time=0,
                                 schema_count=0)
        self._new_chunk()

    def _new_chunk(self) -> None:
        self._parts: list[bytes] = []    # the chunk's uncompressed records
        self._size = 0
        self._n = 0
        self._start = self._end = 0
        self._index: dict[int, list[np.ndarray]] = {}   # channel -> index entries, in first-seen order

    def _flush(self) -> None:
        data = self._out.end()
        self._crc = zlib.crc32(data, self._crc)
        self._stream.write(data)

    def start(self, profile: str = '', library: str = LIBRARY_IDENTIFIER) -> None:
        self._stream.write(MCAP0_MAGIC)
        self._crc = zlib.crc32(MCAP0_MAGIC, self._crc)
        Header(profile, library).write(self._out)
        self._flush()

    def _add_to_chunk(self, record) -> None:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._parts.append(data)
        self._size += len(data)
        if self._size > self._chunk_size:
            self._finish_chunk()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas[schema.id] = schema
        self._stats.schema_count += 1
        self._add_to_chunk(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=metadata)
        self._channels[channel.id] = channel
        self._stats.channel_count += 1
        self._add_to_chunk(channel)
        return channel.id

    def add_message(self, channel: int, log_time: int, data: bytes, publish_time: int | None = None) -> None:
        """One message (sequence 0; publish time = log time unless given)."""
        head = struct.pack('<BQHIQQ', Opcode.MESSAGE, len(data) + 22, channel, 0, log_time,
                           log_time if publish_time is None else publish_time)
        stats, counts = self._stats, self._stats.channel_message_counts
        stats.message_start_time = log_time if stats.message_count == 0 else min(stats.message_start_time, log_time)
        stats.message_end_time = max(stats.message_end_time, log_time)
        stats.message_count += 1
        counts[channel] = counts.get(channel, 0) + 1
        self._start = log_time if self._n == 0 else min(self._start, log_time)
        self._end = max(self._end, log_time)
        parts = self._index.setdefault(channel, [])
        if parts and isinstance(parts[-1], list):   # a run of single messages: tuples, made an array once
            parts[-1].append((log_time, self._size))
        else:
            parts.append([(log_time, self._size)])
        self._parts += (head, data)
        self._size += len(data) + 31
        self._n += 1
        if self._size > self._chunk_size:
            self._finish_chunk()

    def add_messages(self, channels, log_times, data, publish_times=None) -> None:
        """Message k: data[k] on channel id channels[k] at log_times[k] (ns); publish time = log
        time unless given; sequence 0."""
        n = len(data)
        if n == 0:
            return
        head = np.zeros(n, _MESSAGE_HEAD)
        sizes = np.fromiter(map(len, data), np.int64, n)
        head['op'], head['length'] = Opcode.MESSAGE, sizes + 22
        head['channel'], head['log_time'] = channels, log_times
        head['publish_time'] = log_times if publish_times is None else publish_times
        stats, counts = self._stats, self._stats.channel_message_counts
        log = head['log_time']
        stats.message_start_time = int(log.min()) if stats.message_count == 0 else min(stats.message_start_time,
                                                                                      int(log.min()))
        stats.message_end_time = max(stats.message_end_time, int(log.max()))
        stats.message_count += n
        for ch in dict.fromkeys(head['channel'].tolist()):
            counts[ch] = counts.get(ch, 0)
        for ch, k in zip(*np.unique(head['channel'], return_counts=True)):
            counts[int(ch)] += int(k)
        record = sizes + 31
        heads, width = head.tobytes(), _MESSAGE_HEAD.itemsize
        j = 0
        while j < n:   # fill the chunk up to the message that takes it past chunk_size
            ends = self._size + np.cumsum(record[j:])
            k = j + min(int(np.searchsorted(ends, self._chunk_size, side='right')), n - 1 - j)
            offsets = np.concatenate([[self._size], ends[:k - j]])
            self._index_messages(head[j:k + 1], offsets)
            self._parts += [b for i in range(j, k + 1) for b in (heads[i * width:(i + 1) * width], data[i])]
            self._size = int(ends[k - j])
            self._n += k + 1 - j
            if self._size > self._chunk_size:
                self._finish_chunk()
            j = k + 1

    def _index_messages(self, head: np.ndarray, offsets: np.ndarray) -> None:
        log = head['log_time']
        lo, hi = int(log.min()), int(log.max())
        self._start = lo if self._n == 0 else min(self._start, lo)
        self._end = max(self._end, hi)
        ch = head['channel']
        for c in dict.fromkeys(ch.tolist()):   # first-seen order, as mcap's ChunkBuilder
            entries = np.zeros(int(np.count_nonzero(ch == c)), _INDEX_ENTRY)
            entries['log_time'], entries['offset'] = log[ch == c], offsets[ch == c]
            self._index.setdefault(c, []).append(entries)

    def _finish_chunk(self) -> None:
        if self._n == 0:
            return
        self._stats.chunk_count += 1
        raw = b''.join(self._parts)
        packed = zstandard.compress(raw)
        chunk = Chunk(compression='zstd', data=packed, message_start_time=self._start, message_end_time=self._end,
                      uncompressed_crc=zlib.crc32(raw), uncompressed_size=len(raw))
        self._flush()
        start = self._stream.tell()
        chunk.write(self._out)
        index = ChunkIndex(message_start_time=self._start, message_end_time=self._end, chunk_start_offset=start,
                           chunk_length=self._out.count, message_index_offsets={}, message_index_length=0,
                           compression='zstd', compressed_size=len(packed), uncompressed_size=len(raw))
        self._flush()
        index_start = self._stream.tell()
        blocks = []
        for c, parts in self._index.items():
            index.message_index_offsets[c] = index_start + sum(map(len, blocks))
            entries = np.concatenate([np.array(p, _INDEX_ENTRY) if isinstance(p, list) else p for p in parts])
            blocks.append(bytes([Opcode.MESSAGE_INDEX]) + int(6 + entries.nbytes).to_bytes(8, 'little')
                          + c.to_bytes(2, 'little') + entries.nbytes.to_bytes(4, 'little') + entries.tobytes())
        data = b''.join(blocks)
        index.message_index_length = len(data)
        self._crc = zlib.crc32(data, self._crc)
        self._stream.write(data)
        self._chunk_indexes.append(index)
        self._new_chunk()

    def flush(self) -> None:
        self._finish_chunk()
        self._flush()
        self._stream.flush()

    def add_metadata(self, name: str, data: dict) -> None:
        self._flush()
        offset = self._stream.tell()
        self._stats.metadata_count += 1
        Metadata(name=name, metadata=data).write(self._out)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._out.count, name=name))
        self._flush()

    def finish(self) -> None:
        """Data end, summary (schemas, channels, statistics, chunk and metadata indexes, offsets), footer."""
        self._finish_chunk()
        DataEnd(self._crc).write(self._out)
        self._flush()
        start = self._stream.tell()
        summary, offsets = RecordBuilder(), []
        for opcode, records in [(Opcode.SCHEMA, self._schemas.values()), (Opcode.CHANNEL, self._channels.values()),
                                (Opcode.STATISTICS, [self._stats]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                                (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, self._metadata_indexes)]:
            group = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=start + group,
                                         group_length=summary.count - group))
        offset_start = start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 20, start if data else 0, offset_start),
                         zlib.crc32(data))
        self._stream.write(data)
        Footer(summary_start=start if data else 0, summary_offset_start=offset_start, summary_crc=crc).write(self._out)
        self._flush()
        self._stream.write(MCAP0_MAGIC)


class _McapStorage:
    """rosbags' storage-writer interface over `McapFile` (chunk and summary CRCs on)."""

    def __init__(self, path, compression: CompressionMode):
        if compression != CompressionMode.STORAGE:
            raise ValueError('bags are written with zstd chunks (CompressionMode.STORAGE)')
        self.path = path / f'{path.name}.mcap'
        self._file = self.path.open('xb')
        self._mcap = McapFile(self._file)
        self._mcap.start(profile='ros2', library=f'rosbags-{version("rosbags")}; {LIBRARY_IDENTIFIER}')
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}   # rosbags connection id -> mcap channel id

    def add_msgtype(self, connection) -> None:
        encoding = 'ros2msg' if connection.msgdef.format == MessageDefinitionFormat.MSG else 'ros2idl'
        self._schemas[connection.msgtype] = self._mcap.register_schema(
            connection.msgtype, encoding, connection.msgdef.data.encode())

    def add_connection(self, connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._mcap.register_channel(
            connection.topic, connection.ext.serialization_format, self._schemas[connection.msgtype],
            {'offered_qos_profiles': offered_qos_profiles, 'topic_type_hash': connection.digest})

    def write(self, connection, timestamp: int, data) -> None:
        # rosbag2 Jazzy sets publish time = log time when the transport gives no send time
        self._mcap.add_message(self._channels[connection.id], timestamp, bytes(data))

    def write_many(self, channels: list[int], which: list[int], timestamps: list[int], data) -> None:
        """Record k: data[k] on rosbags connection id channels[which[k]] at timestamps[k]."""
        ids = np.array([self._channels[c] for c in channels], np.uint16)
        self._mcap.add_messages(ids[np.asarray(which, np.int64)], timestamps,
                                [d if isinstance(d, bytes) else bytes(d) for d in data])

    def close(self, version_: int, metadata: str) -> None:
        self._mcap.flush()   # the last chunk before the metadata record, as rosbag2 orders them
        self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
        self._mcap.finish()
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class Rosbag2Writer(Writer):
    """rosbags' rosbag2 Writer whose mcap files carry CRCs and the channel metadata rosbag2 writes."""
    STORAGE_PLUGINS = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage}

    def write_many(self, connections: list, which: list[int], timestamps: list[int], data) -> None:
        """Many `write`s in one call: record k is data[k] on connections[which[k]] at timestamps[k]
        (ns). The checks and bookkeeping of `Writer.write` are done once per call, not per message."""
        if not isinstance(self.storage, _McapStorage) or self.compression_mode == CompressionMode.MESSAGE:
            for k, t, d in zip(which, timestamps, data):
                self.write(connections[k], t, d)
            return
        for conn in connections:
            if conn not in self.connections:
                raise WriterError(f'Tried to write to unknown connection {conn!r}.')
        self.storage.write_many([c.id for c in connections], which, timestamps, data)
        counts = Counter(which)
        for k, conn in enumerate(connections):
            self.counts[conn.id] += counts.get(k, 0)
        if timestamps:
            self.min_timestamp = min(self.min_timestamp, min(timestamps))
            self.max_timestamp = max(self.max_timestamp, max(timestamps))
