"""ROS 2 bags (rosbag2 folders, bare .mcap files) through `bag_io.BagReader`, with any topic names
(`--topic STREAM=/name`). The package's own bags are this source with the default names."""
from __future__ import annotations

import json
from typing import Iterator

from .. import topics
from ..bag_io import BagReader
from ..samples import SensorChunk
from .base import Source


class Rosbag2Source(Source):
    kind, label = 'rosbag2', 'ROS 2 bag'
    has_truth_format = True

    def __init__(self, path, topic_map: dict[str, str] | None = None):
        super().__init__(path)
        self.topic_map = dict(topic_map or {})
        self.reader = BagReader(path, self.topic_map).__enter__()   # BagError: not a bag, wrong types
        self.time_origin_ns = self.reader.time_origin_ns
        for text in self.reader.text(topics.SIM_CONFIG)[:1]:
            try:
                config = json.loads(text)
            except ValueError:
                continue
            self.metadata.update({f'sim.{k}': v for k, v in config.items() if isinstance(v, (str, int, float))})

    def close(self) -> None:
        self.reader.__exit__(None, None, None)

    def streams_present(self) -> dict[str, str]:
        return self.reader.streams_present()

    def span_s(self) -> tuple[float, float]:
        lo, hi = self._window
        start, end = self.reader.start_time_s, self.reader.start_time_s + self.reader.duration_s
        return (start if lo is None else max(start, lo)), (end if hi is None else min(end, hi))

    def rate_hz(self, stream: str) -> float | None:
        topic = self.streams_present().get(stream)
        info = next((t for t in self.reader.topics if t.topic == topic), None)
        dur = self.reader.duration_s
        return (info.count - 1) / dur if info is not None and info.count > 1 and dur > 0 else None

    def _chunks(self, chunk_s: float, streams: list[str]) -> Iterator[SensorChunk]:
        return self.reader.chunks(chunk_s, streams)
