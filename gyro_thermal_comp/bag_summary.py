"""A one-screen summary of a bag: what is in it and whether the numbers look physical."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import topics
from .bag_io import BagReader


@dataclass
class BagSummary:
    path: str
    duration_s: float
    topics: dict = field(default_factory=dict)      # topic -> {type, count, rate_hz}
    temperature_c: tuple | None = None                # (min, max)
    gyro_mean_deg_s: list | None = None               # per axis, whole record
    gyro_bias_truth_mean_deg_s: list | None = None
    mag_norm_ut: tuple | None = None                  # (min, max)
    disturbed_s: float | None = None                  # time with a magnetic disturbance (truth)
    scenario: str | None = None
    truncated: bool = False

    def to_dict(self) -> dict:
        return asdict(self)

    def to_text(self) -> str:
        lines = [f'{self.path}: {self.duration_s:.1f} s' + (f', scenario {self.scenario}' if self.scenario else '')
                 + (' [TRUNCATED]' if self.truncated else '')]
        for topic, info in self.topics.items():
            lines.append(f'  {topic:32s} {info["type"]:36s} {info["count"]:8d} msgs {info["rate_hz"]:8.2f} Hz')
        if self.temperature_c:
            lines.append(f'  temperature {self.temperature_c[0]:.2f} .. {self.temperature_c[1]:.2f} degC')
        if self.gyro_mean_deg_s:
            lines.append('  gyro mean (deg/s) ' + ' '.join(f'{v:+.5f}' for v in self.gyro_mean_deg_s))
        if self.gyro_bias_truth_mean_deg_s:
            lines.append('  true drift mean (deg/s) ' + ' '.join(f'{v:+.5f}' for v in self.gyro_bias_truth_mean_deg_s))
        if self.mag_norm_ut:
            lines.append(f'  |B| {self.mag_norm_ut[0]:.2f} .. {self.mag_norm_ut[1]:.2f} uT')
        if self.disturbed_s is not None:
            lines.append(f'  magnetic disturbance (truth) for {self.disturbed_s:.1f} s')
        return '\n'.join(lines)


class _Running:
    """Streaming sum / min / max so summaries never hold a whole bag."""

    def __init__(self):
        self.n, self.total, self.lo, self.hi = 0, 0.0, np.inf, -np.inf

    def add(self, values: np.ndarray) -> None:
        if len(values):
            self.n += len(values)
            self.total = self.total + values.sum(axis=0)
            self.lo, self.hi = np.minimum(self.lo, values.min(axis=0)), np.maximum(self.hi, values.max(axis=0))

    @property
    def mean(self):
        return self.total / self.n if self.n else None


def summarize_bag(path) -> BagSummary:
    path = Path(path)
    with BagReader(path) as reader:
        duration = reader.duration_s
        summary = BagSummary(str(path), duration)
        for info in reader.topics:
            rate = (info.count - 1) / duration if duration > 0 and info.count > 1 else 0.0
            summary.topics[info.topic] = {'type': info.msgtype, 'count': info.count, 'rate_hz': rate}
        configs = reader.text(topics.SIM_CONFIG) if topics.SIM_CONFIG in summary.topics else []
        if configs:
            summary.scenario = json.loads(configs[0]).get('scenario')
        temp, gyro, bias, mag = _Running(), _Running(), _Running(), _Running()
        disturbed, dist_dt, stamps = 0, None, {}
        for chunk in reader.chunks(600.0):
            for name, samples in chunk.streams().items():  # per-stream span -> its own rate
                n, first, _ = stamps.get(name, (0, samples.t[0], None))
                stamps[name] = (n + len(samples.t), first, samples.t[-1])
            if chunk.temperature is not None:
                temp.add(chunk.temperature.temp_c)
            if chunk.imu is not None:
                gyro.add(chunk.imu.gyro)
            if chunk.gyro_bias is not None:
                bias.add(chunk.gyro_bias.vec)
            if chunk.mag is not None:
                mag.add(np.linalg.norm(chunk.mag.field, axis=1))
            if chunk.mag_disturbance is not None and len(chunk.mag_disturbance.t) > 1:
                dist_dt = float(np.median(np.diff(chunk.mag_disturbance.t)))
                disturbed += int(np.count_nonzero(np.linalg.norm(chunk.mag_disturbance.vec, axis=1) > 0))
        summary.truncated = reader.truncated
        present = reader.streams_present()
        for name, (n, first, last) in stamps.items():
            topic = present[name]
            if n > 1 and last > first and topic in summary.topics:
                summary.topics[topic]['rate_hz'] = (n - 1) / (last - first)
    if temp.n:
        summary.temperature_c = (float(temp.lo), float(temp.hi))
    if gyro.n:
        summary.gyro_mean_deg_s = np.degrees(gyro.mean).tolist()
    if bias.n:
        summary.gyro_bias_truth_mean_deg_s = np.degrees(bias.mean).tolist()
    if mag.n:
        summary.mag_norm_ut = (float(mag.lo) * 1e6, float(mag.hi) * 1e6)
    if dist_dt is not None:
        summary.disturbed_s = disturbed * dist_dt
    return summary
