"""rosbag2 reading: a bag (rosbag2 folder or bare .mcap file) as a stream of time-ordered SensorChunks.

Streaming keeps an hours-long 1 kHz bag from ever sitting in memory whole. An intact bag is read
through rosbags' indexed reader; a damaged or unfinished mcap file is streamed record by record up to
its first broken record, with a BagWarning. Messages are decoded to samples by bag_messages.py.

Speed: Imu, MagneticField and Temperature are decoded as arrays (cdr.py), other types message by
message through rosbags; `chunks(keep_raw=True)` also hands out the records as stored (`RawRecords`),
for `BagWriter.write_raw_records` to copy them without re-serialising.

Time: sample times in chunks are float seconds since a time origin (stamps.py), never since 1970: a
reader's `time_origin_ns` is the log time of the bag's first message. Log times are integer ns since 1970.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np
from rosbags.rosbag2 import Reader

from . import cdr, topics
from .bag_errors import BagError, BagWarning
from .bag_messages import FAST, READERS, header_stamp_s, seconds_since_many
from .cdr import TYPESTORE
from .samples import SensorChunk


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: its name, message type and message count."""
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
        unknown = set(topic_map or {}) - set(READERS)
        if unknown:
            raise BagError(f'unknown stream(s) {sorted(unknown)}; known: {sorted(READERS)}')
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
            if name is not None and info.msgtype not in READERS[name][1]:
                self._source.close()
                expected = ' or '.join(sorted(READERS[name][1]))
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
        return header_stamp_s(header, self.time_origin_ns)

    def streams_present(self) -> dict[str, str]:
        """Stream name -> bag topic, for the streams this bag actually holds (at least one message)."""
        by_topic = {info.topic: info.msgtype for info in self.topics if info.count > 0}
        return {name: topic for name, topic in self.topic_map.items()
                if by_topic.get(topic) in READERS[name][1]}

    def _topic_hint(self) -> str:
        """'; map its topics with --topic ...' naming the topics of a type the package reads that
        no stream is mapped to ('' if there are none)."""
        mapped = set(self.topic_map.values())
        readable = set().union(*(types for _, types, _, _ in READERS.values()))
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
            fast = FAST.get(name)
            if fast is not None and fast[0] == msgtype:
                decoded = cdr.decode([records[k][3] for k in pos.tolist()], msgtype)
                for i, exc in decoded.errors:
                    self._undecodable(topic, msgtype, exc)
                t = seconds_since_many(decoded.stamp_ns, self.time_origin_ns)
                rows.setdefault(name, []).append(
                    (pos[decoded.index], np.column_stack([t, *(decoded.fields[f] for f in fast[1])])))
                ok_pos.append(pos[decoded.index])
                ok_t.append(t)
                continue
            extract, width = READERS[name][0], READERS[name][2]
            good, good_t, kept, kept_rows = [], [], [], []
            for k in pos.tolist():
                try:
                    msg = TYPESTORE.deserialize_cdr(records[k][3], msgtype)
                except Exception as exc:
                    self._undecodable(topic, msgtype, exc)
                    continue
                row = extract(msg, self.time_origin_ns)
                good.append(k)
                good_t.append(header_stamp_s(msg.header, self.time_origin_ns) if row is None else row[0])
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
                streams[name] = READERS[name][3](block)
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
