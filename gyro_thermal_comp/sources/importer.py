"""`import_recording`: any recording (`open_source`) into rosbag2 folders with the package's topics.

Two passes over the source. The first bins it (static_periods.RecordBins) and checks it: the gyro
must turn the way the accelerometer and magnetometer turn (frames.KinematicCheck), and at rest the
imported z axis must point up (within frames.UP_TOLERANCE_DEG). The second writes, through
`bag_io.BagWriter`, at the source's own stamps (UTC where the source knows it):

- one bag with the streams as they are (the up check must pass);
- `level=True`: one bag rotated so that its rest orientation's vertical is +z (the window must rest
  in one orientation);
- `split_static=True`: a folder with one bag per static period (`period_1`, ...), each levelled
  by its own rotation.

Every bag also carries `/import/source` (std_msgs/String, JSON): where it came from, the window,
the rotation applied, the notes and what was dropped. Outputs appear only when complete.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import topics
from ..bag_io import BagError, BagWriter
from ..samples import ImuSamples, MagSamples, SensorChunk, slice_samples
from . import frames, open_source
from .base import Source, SourceError
from .static_periods import MIN_STATIC_S, RecordBins, StaticPeriod, find_static_periods, rest_up_angle_deg, still_bins
from .timebase import format_utc

SENSOR_STREAMS = ('imu', 'mag', 'temperature')
IMPORT_SOURCE = topics.IMPORT_SOURCE
KINEMATIC_BIN_S = 0.05


@dataclass
class ImportedBag:
    path: Path
    start_utc: str
    duration_s: float
    counts: dict
    rotation: list | None          # applied to every vector (proper rotation), None: none
    up_angle_deg: float | None     # at rest, after the rotation
    period: StaticPeriod | None = None

    def to_text(self) -> str:
        rot = '' if self.rotation is None else f', levelled (rotation {np.round(np.asarray(self.rotation), 4).tolist()})'
        up = '' if self.up_angle_deg is None else f', z {self.up_angle_deg:.1f} deg from up at rest'
        return (f'wrote {self.path}: {self.start_utc} + {self.duration_s:.1f} s, '
                + ', '.join(f'{t} {n}' for t, n in self.counts.items()) + rot + up)


@dataclass
class ImportResult:
    description: str
    kind: str
    bags: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    dropped: str = ''

    def to_text(self) -> str:
        return '\n'.join([self.description, *(f'  {n}' for n in self.notes), f'  {self.dropped}',
                          *(b.to_text() for b in self.bags)])


def import_recording(src, out, *, topic_map=None, column_map=None, imu: int | None = None, start=None, end=None,
                     period: str | None = None, level: bool = False, split_static: bool = False,
                     min_static_s: float = MIN_STATIC_S, overwrite: bool = False) -> ImportResult:
    """Convert `src` (any format `open_source` reads; its options are passed on) into rosbag2 at `out`:
    a bag folder, or with `split_static` a folder of bags. SourceError / BagError (one line) for
    input that cannot be imported as asked; nothing is left at `out` then."""
    if level and split_static:
        raise SourceError('--level and --split-static: choose one (each static period is levelled anyway)')
    out = Path(out)
    if out.exists() and not overwrite:
        raise SourceError(f'output {out} already exists (use --force to overwrite)')
    if not out.parent.is_dir():
        raise SourceError(f'cannot write {out}: folder {out.parent} does not exist')
    with open_source(src, topic_map=topic_map, column_map=column_map, imu=imu, start=start, end=end,
                     period=period) as source:
        source.require('imu')
        bins, kinematic = _first_pass(source)
        result = ImportResult(source.describe(), source.kind, notes=list(source.notes))
        verdict, text = kinematic.verdict()
        if verdict == 'mirrored':
            raise SourceError(f'{source.path}: the gyro turns opposite to the accelerometer and magnetometer ({text}): '
                              'its axes are mirrored relative to theirs'
                              + ('; set gyro_transform in the column map' if source.kind == 'table' else ''))
        if verdict == 'scale':
            raise SourceError(f'{source.path}: the gyro turns the accelerometer and magnetometer by a different amount '
                              f'than they turn ({text}): is its unit right?')
        result.notes.append(text)
        provenance = {'source': str(source.path), 'format': source.label, 'description': result.description,
                      'notes': result.notes, 'topic_map': topic_map, 'imu': imu,
                      'column_map': getattr(getattr(source, 'map', None), 'source', None) or None}
        if split_static:
            periods = find_static_periods(bins, min_static_s=min_static_s)
            if not periods:
                raise SourceError(f'{source.path}: no static period of {min_static_s:g} s or more '
                                  '(at rest: specific force steady in direction and size, rate steady)')
            result.bags = _write_periods(source, periods, out, overwrite, provenance)
        else:
            rotation, up_deg = _whole_record_rotation(source, bins, level, min_static_s)
            result.bags = [_write_bag(source, out, overwrite, rotation, up_deg, None, None, provenance)]
        result.dropped = source.dropped.to_text()
        return result


def _bin_means(t: np.ndarray, v: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    if len(t) < 2 or float(np.median(np.diff(t))) >= width:
        return t, v
    k = np.floor((t - t[0]) / width).astype(np.int64)
    _, start = np.unique(k, return_index=True)
    n = np.diff(np.r_[start, len(k)])
    return np.add.reduceat(t, start) / n, np.add.reduceat(v, start, axis=0) / n[:, None]


def _first_pass(source: Source):
    bins = RecordBins()
    accel_check, mag_check = frames.KinematicCheck(), frames.KinematicCheck()
    for chunk in source.chunks(60.0, ['imu', 'mag']):
        bins.add(chunk)
        if chunk.imu is not None:
            t, w = _bin_means(chunk.imu.t, chunk.imu.gyro, KINEMATIC_BIN_S)
            _, f = _bin_means(chunk.imu.t, chunk.imu.accel, KINEMATIC_BIN_S)
            accel_check.add(t, w, f)
            if chunk.mag is not None and len(chunk.mag.t) > 1:
                m = np.column_stack([np.interp(t, chunk.mag.t, chunk.mag.field[:, k]) for k in range(3)])
                inside = (t >= chunk.mag.t[0]) & (t <= chunk.mag.t[-1])
                mag_check.add(t[inside], w[inside], m[inside])
    accel_check.merge(mag_check)
    return bins.finish(), accel_check


def _whole_record_rotation(source: Source, bins: dict, level: bool, min_static_s: float):
    """(rotation or None, up angle at rest after it or None); SourceError if z does not point up."""
    if level:
        still = still_bins(bins['accel'], bins['gyro'])
        if not still.any():
            raise SourceError(f'{source.path}: --level needs the unit at rest somewhere; it never is')
        periods = find_static_periods(bins, min_static_s=min(min_static_s, 60.0))
        ups = np.array([p.up for p in periods]) if periods else np.zeros((0, 3))
        if len(ups) > 1 and np.degrees(np.arccos(np.clip(ups @ ups.T, -1, 1))).max() > 10.0:
            raise SourceError(f'{source.path}: it rests in {len(ups)} orientations; --level needs one (use '
                              '--split-static, or --start/--end)')
        d = bins['accel'][still] / np.linalg.norm(bins['accel'][still], axis=1)[:, None]
        R = frames.levelling_rotation(d.mean(axis=0))
        return R, frames.up_angle_deg(R @ d.mean(axis=0))
    angle, n = rest_up_angle_deg(bins['accel'], bins['gyro'])
    if n == 0:
        source.notes.append('never at rest: the up check was not made')
        return None, None
    if angle > frames.UP_TOLERANCE_DEG:
        raise SourceError(f'{source.path}: at rest the imported z axis points {angle:.0f} deg from up ({n} still '
                          's); declare the logger\'s axes (column map `axes`), or --level / --split-static to '
                          'rotate each rest orientation upright')
    return None, angle


def _rotated(chunk: SensorChunk, R: np.ndarray | None, lo: float | None, hi: float | None,
             streams: tuple[str, ...]) -> SensorChunk:
    out = {}
    for name, s in chunk.streams().items():
        if name not in streams:
            continue
        keep = np.ones(len(s.t), bool)
        if lo is not None:
            keep &= s.t >= lo
        if hi is not None:
            keep &= s.t < hi
        if not keep.any():
            continue
        s = s if keep.all() else slice_samples(s, keep)
        if R is not None and isinstance(s, ImuSamples):
            s = ImuSamples(s.t, frames.rotate_rows(R, s.gyro), frames.rotate_rows(R, s.accel))
        elif R is not None and isinstance(s, MagSamples):
            s = MagSamples(s.t, frames.rotate_rows(R, s.field))
        out[name] = s
    return SensorChunk(**out)


def _write_bag(source: Source, path: Path, overwrite: bool, R, up_deg, period: StaticPeriod | None,
               window: tuple | None, provenance: dict) -> ImportedBag:
    lo, hi = window or (None, None)
    # a rotated record's truth orientation would need rotating too: only sensor streams then
    streams = SENSOR_STREAMS if R is not None else tuple(source.streams_present())
    dropped_truth = sorted(set(source.streams_present()) - set(streams))
    first = last = None
    with BagWriter(path, overwrite=overwrite, time_origin_ns=source.time_origin_ns) as writer:
        span = source.span_s()
        info = dict(provenance, rotation=None if R is None else np.asarray(R).tolist(), up_angle_deg=up_deg,
                    window_utc=[format_utc(source.time_origin_ns + int((v if v is not None else d) * 1e9))
                                for v, d in ((lo, span[0]), (hi, span[1]))],
                    left_out=dropped_truth or None,
                    period=None if period is None else {'start_s': period.start_s, 'end_s': period.end_s,
                                                         'up': list(period.up)})
        writer.write_text(IMPORT_SOURCE, lo if lo is not None else span[0], json.dumps(info, sort_keys=True))
        for chunk in source.chunks(60.0, streams):
            chunk = _rotated(chunk, R, lo, hi, streams)
            if not chunk.streams():
                continue
            writer.write_chunk(chunk)
            if chunk.imu is not None and len(chunk.imu.t):
                first = float(chunk.imu.t[0]) if first is None else first
                last = float(chunk.imu.t[-1])
        if first is None:
            raise SourceError(f'{source.path}: no IMU sample to write' + (f' in {path.name}' if window else ''))
    counts = {t: n for t, n in writer.counts.items() if t != IMPORT_SOURCE}
    return ImportedBag(path, format_utc(source.time_origin_ns + int(first * 1e9)), last - first, counts,
                       None if R is None else np.asarray(R).tolist(), up_deg, period)


def _write_periods(source: Source, periods: list[StaticPeriod], out: Path, overwrite: bool,
                   provenance: dict) -> list[ImportedBag]:
    """One levelled bag per period in a folder that appears at `out` only when all are written."""
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f'.{out.name}.', suffix='.partial', dir=out.parent))
    except OSError as exc:
        raise BagError(f'cannot write {out}: {exc.strerror or exc}') from None
    try:
        bags = []
        for k, p in enumerate(periods, 1):
            R = p.rotation()
            up = frames.up_angle_deg(R @ np.asarray(p.up))
            bags.append(_write_bag(source, tmp / f'period_{k}', False, R, up, p, (p.start_s, p.end_s), provenance))
        (tmp / 'periods.json').write_text(json.dumps([
            {'bag': f'period_{k}', 'start_utc': b.start_utc, 'duration_s': b.duration_s, 'up_sensor_frame': list(p.up),
             'rotation': b.rotation, 'still_fraction': p.still_fraction}
            for k, (b, p) in enumerate(zip(bags, periods), 1)], indent=1))
        if out.exists() or out.is_symlink():
            if not overwrite:
                raise SourceError(f'output {out} already exists (use --force to overwrite)')
            shutil.rmtree(out) if out.is_dir() and not out.is_symlink() else out.unlink()
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    for b in bags:
        b.path = out / b.path.name
    return bags



@contextlib.contextmanager
def package_bag(src, *, topic_map=None, column_map=None, imu: int | None = None, start=None, end=None,
                period: str | None = None):
    """(rosbag2 path, topic map, ImportResult or None) of any recording, for code that reads bags by
    their records (a replay copies its inputs as recorded): a ROS 2 bag as it is, with its topic map;
    any other recording (or a time window) imported into a temporary bag that lives as long as the
    block, with what the import found (which IMU, axes, what was dropped)."""
    from . import detect_kind
    from .topic_map import parse_topic_map
    windowed = start is not None or end is not None or period is not None
    if detect_kind(src) == 'rosbag2' and not windowed and column_map is None and imu is None:
        yield Path(src), parse_topic_map(topic_map) or None, None
        return
    with tempfile.TemporaryDirectory(prefix='gtc-import-') as tmp:
        bag = Path(tmp) / Path(src).stem
        result = import_recording(src, bag, topic_map=topic_map, column_map=column_map, imu=imu, start=start,
                                  end=end, period=period)
        yield bag, None, result
