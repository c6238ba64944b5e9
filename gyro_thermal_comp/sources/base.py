"""`Source`: a recording of any format as the package's `SensorChunk`s, and what reading it dropped.

Every reader in this package (`sources/*.py`) is a `Source`: a context manager with
`streams_present()`, `chunks(chunk_s, streams)` (callable again, each call from the start),
`time_origin_ns` (chunk times are s since it, as bag_io's reader gives them), `metadata` (what the
log says about itself: parameters, hardware ids; `calibrate --unit field:NAME` reads it),
`notes` (one-line facts the reader established: which IMU, which axes, which time base) and
`dropped` (`DropReport`: what was left out and why).

`ArraySource` holds whole streams in memory (flight logs and tables are read whole by their
libraries anyway) and cuts them into chunks; the bag readers stream.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..samples import SensorChunk, slice_samples


class SourceError(ValueError):
    """A recording that cannot be read as asked (not what it claims to be, a bad column map, units
    that cannot be right, a stream that is not there): one line meant for the user (exit 2)."""


@dataclass
class DropReport:
    """Samples left out per stream and reason, and time gaps seen (kept: nothing is invented)."""
    dropped: dict = field(default_factory=dict)     # stream -> {reason: count}
    gaps: dict = field(default_factory=dict)        # stream -> (count, largest gap s)

    def add(self, stream: str, reason: str, count: int) -> None:
        if count:
            per = self.dropped.setdefault(stream, {})
            per[reason] = per.get(reason, 0) + int(count)

    def merge(self, other: 'DropReport') -> None:
        for stream, per in other.dropped.items():
            for reason, n in per.items():
                self.add(stream, reason, n)
        for stream, (n, largest) in other.gaps.items():
            old = self.gaps.get(stream, (0, 0.0))
            self.gaps[stream] = (old[0] + n, max(old[1], largest))

    def to_text(self) -> str:
        """One line: 'dropped: imu 3 not finite; gaps: temperature 2 (largest 5.0 s)' or 'nothing dropped'."""
        parts = [f'{s} ' + ', '.join(f'{n} {r}' for r, n in per.items()) for s, per in self.dropped.items()]
        gaps = [f'{s} {n} (largest {g:.3g} s)' for s, (n, g) in self.gaps.items() if n]
        text = ('dropped: ' + '; '.join(parts)) if parts else 'nothing dropped'
        return text + ('; gaps: ' + '; '.join(gaps) if gaps else '')

    def to_dict(self) -> dict:
        return {'dropped': self.dropped, 'gaps': {s: {'count': n, 'largest_s': g} for s, (n, g) in self.gaps.items()}}


class Source:
    """Base of every reader: see the module docstring. Subclasses set `kind` and implement
    `streams_present`, `_chunks` and `span_s`."""
    kind = ''          # 'rosbag2', 'rosbag1', 'ulog', 'dataflash', 'table'
    label = ''         # what a user calls it: 'PX4 ULog', 'ROS 1 bag', ...
    has_truth_format = False   # a format that can carry ground truth (the package's own bags)

    def __init__(self, path):
        self.path = Path(path)
        self.time_origin_ns = 0
        self.metadata: dict = {}
        self.notes: list[str] = []
        self.dropped = DropReport()
        self._window: tuple[float | None, float | None] = (None, None)

    def __enter__(self) -> 'Source':
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def close(self) -> None:
        pass

    # ------------------------------------------------------------------ what is there
    def streams_present(self) -> dict[str, str]:
        """Stream name (SensorChunk field) -> where it comes from (topic, message, column)."""
        raise NotImplementedError

    def require(self, *streams: str) -> dict[str, str]:
        present = self.streams_present()
        missing = [s for s in streams if s not in present]
        if missing:
            raise SourceError(f'{self.label} {self.path} has no {" or ".join(missing)} stream'
                              + (f' (it has: {", ".join(present)})' if present else ''))
        return present

    @property
    def has_heading_truth(self) -> bool:
        return 'odom' in self.streams_present()

    def span_s(self) -> tuple[float, float]:
        """First and last sample time, s since time_origin_ns (inside the selected window)."""
        raise NotImplementedError

    @property
    def duration_s(self) -> float:
        lo, hi = self.span_s()
        return max(0.0, hi - lo)

    @property
    def start_time_s(self) -> float:
        return self.span_s()[0]

    def rate_hz(self, stream: str) -> float | None:
        """Median sample rate of a stream (None if it has fewer than two samples)."""
        return None

    # ------------------------------------------------------------------ time window
    def select(self, start_s: float | None = None, end_s: float | None = None) -> 'Source':
        """Keep only samples with start_s <= t < end_s (s since time_origin_ns); returns self."""
        self._window = (start_s, end_s)
        return self

    def _in_window(self, chunk: SensorChunk) -> SensorChunk:
        lo, hi = self._window
        if lo is None and hi is None:
            return chunk
        out = {}
        for name, s in chunk.streams().items():
            keep = np.ones(len(s.t), bool)
            if lo is not None:
                keep &= s.t >= lo
            if hi is not None:
                keep &= s.t < hi
            if keep.any():
                out[name] = s if keep.all() else slice_samples(s, keep)
        return SensorChunk(**out)

    # ------------------------------------------------------------------ data
    def chunks(self, chunk_s: float = 60.0, streams: Iterable[str] | None = None) -> Iterator[SensorChunk]:
        """Time-ordered chunks of about `chunk_s` each (streams default: all present)."""
        wanted = list(self.streams_present()) if streams is None else [s for s in streams
                                                                         if s in self.streams_present()]
        if not wanted:
            raise SourceError(f'{self.label} {self.path} has none of the streams {", ".join(streams or [])}')
        for chunk in self._chunks(chunk_s, wanted):
            chunk = self._in_window(chunk)
            if chunk.streams():
                yield chunk

    def _chunks(self, chunk_s: float, streams: list[str]) -> Iterator[SensorChunk]:
        raise NotImplementedError

    def describe(self) -> str:
        """One line: format, path, streams and where they come from."""
        present = self.streams_present()
        parts = []
        for name, origin in present.items():
            rate = self.rate_hz(name)
            parts.append(f'{name} <- {origin}' + (f' ({rate:.4g} Hz)' if rate else ''))
        return f'{self.label} {self.path.name}: ' + ', '.join(parts)


class ArraySource(Source):
    """A source whose streams are held whole (SensorChunk fields of samples, t in s since
    time_origin_ns, increasing)."""

    def __init__(self, path, streams: dict | None = None):
        super().__init__(path)
        self.streams: dict = dict(streams or {})
        self.origins: dict[str, str] = {}

    def streams_present(self) -> dict[str, str]:
        return {name: self.origins.get(name, name) for name, s in self.streams.items()
                if s is not None and len(s.t)}

    def span_s(self) -> tuple[float, float]:
        lo, hi = self._window
        ts = [s.t for s in self.streams.values() if s is not None and len(s.t)]
        if not ts:
            return 0.0, 0.0
        first = min(float(t[np.searchsorted(t, lo)]) if lo is not None and np.searchsorted(t, lo) < len(t)
                    else float(t[0]) for t in ts)
        last = max(float(t[np.searchsorted(t, hi) - 1]) if hi is not None and np.searchsorted(t, hi) > 0
                   else float(t[-1]) for t in ts)
        return first, max(first, last)

    def rate_hz(self, stream: str) -> float | None:
        s = self.streams.get(stream)
        if s is None or len(s.t) < 2:
            return None
        dt = float(np.median(np.diff(s.t)))
        return 1.0 / dt if dt > 0 else None

    def _chunks(self, chunk_s: float, streams: list[str]) -> Iterator[SensorChunk]:
        lo, hi = self.span_s()
        if not self.streams_present():
            return
        edges = np.arange(lo, hi + chunk_s, chunk_s)
        edges[-1] = np.inf
        cursor = dict.fromkeys(streams, 0)
        for k in range(len(edges) - 1):
            parts = {}
            for name in streams:
                s = self.streams[name]
                end = int(np.searchsorted(s.t, edges[k + 1], side='left'))
                if end > cursor[name]:
                    parts[name] = slice_samples(s, slice(cursor[name], end))
                cursor[name] = end
            if parts:
                yield SensorChunk(**parts)


def sample_fields(samples) -> list[str]:
    """Field names of a samples dataclass other than its time."""
    return [f.name for f in fields(samples) if f.name != 't']
