"""The column map: how a table's columns (CSV) or variables (netCDF, HDF5) become the package's
streams. A small YAML file (or the same mapping in Python):

    format: gyro_thermal_comp/column_map/1
    time:                          # omit to stamp samples at rate_hz from 0
      column: timestamp_utc        # numbers, or ISO 8601 text in a CSV
      unit: s                      # s | ms | us | ns; omit for a CF 'seconds since ...' attribute
      epoch: 2021-09-20T08:52:00Z  # UTC of time 0 (default: the CF attribute's, else 1970)
    rate_hz: 1.0                   # declared sample rate: checked against the stamps (optional)
    axes: FRU                      # the logger's x, y, z (frames.py); default: the file's
                                   # `axes` attribute, else FLU
    gyro_transform: pseudovector   # how the gyro follows a mirrored frame (frames.py)
    streams:
      gyro: {column: angular_velocity, unit: mrad/s}     # an (N, 3) variable ...
      accel: {column: [ax, ay, az], unit: m/s^2}         # ... or three columns
      mag: {column: magnetic_density, unit: uT}
      temperature: {column: temperature, unit: degC}
    periods:                       # named UTC ranges for `import --period NAME` (optional)
      '1': [2021-09-20T09:00:00Z, 2021-09-21T10:33:00Z]

gyro and accel are required (they make the IMU stream); mag and temperature are optional. Every
mistake is a SourceError naming the key.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from . import frames, units
from .base import SourceError
from .timebase import parse_utc

FORMAT = 'gyro_thermal_comp/column_map/1'
VECTOR_FIELDS = ('gyro', 'accel', 'mag')
FIELDS = VECTOR_FIELDS + ('temperature',)
_TOP_KEYS = {'format', 'time', 'rate_hz', 'axes', 'gyro_transform', 'streams', 'periods', 'description'}


@dataclass(frozen=True)
class Column:
    names: tuple[str, ...]     # one (a variable, (N, 3) for a vector) or three (columns x, y, z)
    unit: str


@dataclass(frozen=True)
class ColumnMap:
    streams: dict                         # field -> Column
    time_column: str | None = None
    time_unit: str | None = None          # None: from the file's CF attribute
    epoch_ns: int | None = None           # UTC of time 0, ns since 1970 (None: CF attribute or 1970)
    rate_hz: float | None = None
    axes: str | None = None               # None: the file's `axes` attribute, else FLU
    gyro_transform: str = 'pseudovector'
    periods: dict = field(default_factory=dict)   # name -> (start ns, end ns) UTC
    source: str = ''

    @classmethod
    def from_dict(cls, d, source: str = '') -> 'ColumnMap':
        where = f'column map {source}' if source else 'column map'
        if not isinstance(d, dict):
            raise SourceError(f'{where}: expected a mapping with streams, time, axes')
        unknown = sorted(set(d) - _TOP_KEYS)
        if unknown:
            raise SourceError(f'{where}: unknown key(s) {", ".join(map(str, unknown))} (known: {", ".join(sorted(_TOP_KEYS))})')
        if d.get('format', FORMAT) != FORMAT:
            raise SourceError(f"{where}: format must be {FORMAT!r}, got {d.get('format')!r}")
        raw_streams = d.get('streams')
        if not isinstance(raw_streams, dict):
            raise SourceError(f'{where}: streams must map gyro, accel (and mag, temperature) to columns')
        bad = sorted(set(raw_streams) - set(FIELDS))
        if bad:
            raise SourceError(f'{where}: unknown stream(s) {", ".join(map(str, bad))} (known: {", ".join(FIELDS)})')
        missing = [f for f in ('gyro', 'accel') if f not in raw_streams]
        if missing:
            raise SourceError(f'{where}: streams needs {" and ".join(missing)} (they make the IMU stream)')
        streams = {name: _column(name, spec, where) for name, spec in raw_streams.items()}
        time = d.get('time')
        time_column = time_unit = epoch_ns = None
        if time is not None:
            if not isinstance(time, dict) or not isinstance(time.get('column'), str):
                raise SourceError(f'{where}: time must be a mapping with a column name')
            extra = sorted(set(time) - {'column', 'unit', 'epoch'})
            if extra:
                raise SourceError(f'{where}: unknown time key(s) {", ".join(extra)} (known: column, unit, epoch)')
            time_column = time['column']
            if time.get('unit') is not None:
                time_unit = str(time['unit'])
                if time_unit != 'iso8601':
                    units.conversion('time', time_unit)   # SourceError for an unknown unit
            if time.get('epoch') is not None:
                epoch_ns = parse_utc(time['epoch'], f'{where}: time.epoch')
        rate = d.get('rate_hz')
        if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float)) or not rate > 0
                                 or not np.isfinite(rate)):
            raise SourceError(f'{where}: rate_hz must be a positive number, got {rate!r}')
        if time_column is None and rate is None:
            raise SourceError(f'{where}: give a time column or rate_hz (stamps at a fixed rate)')
        axes = None if d.get('axes') is None else str(d['axes'])
        if axes is not None:
            frames.axes_matrix(axes)
        gyro_transform = str(d.get('gyro_transform', 'pseudovector'))
        if gyro_transform not in frames.GYRO_TRANSFORMS:
            raise SourceError(f'{where}: gyro_transform must be one of {", ".join(frames.GYRO_TRANSFORMS)}')
        periods = {}
        for name, span in (d.get('periods') or {}).items():
            if not (isinstance(span, (list, tuple)) and len(span) == 2):
                raise SourceError(f'{where}: period {name} must be [start, end] (UTC)')
            lo, hi = (parse_utc(v, f'{where}: period {name}') for v in span)
            if hi <= lo:
                raise SourceError(f'{where}: period {name} ends before it starts')
            periods[str(name)] = (lo, hi)
        return cls(streams=streams, time_column=time_column, time_unit=time_unit, epoch_ns=epoch_ns,
                   rate_hz=None if rate is None else float(rate), axes=axes, gyro_transform=gyro_transform,
                   periods=periods, source=source)

    @classmethod
    def load(cls, path) -> 'ColumnMap':
        path = Path(path)
        try:
            d = yaml.safe_load(path.read_text())
        except OSError as exc:
            raise SourceError(f'column map {path}: {exc.strerror or exc}') from None
        except yaml.YAMLError as exc:
            raise SourceError(f'column map {path}: not YAML ({str(exc).splitlines()[0]})') from None
        return cls.from_dict(d, str(path))

    def declared_units(self) -> dict[str, str]:
        return {name: col.unit for name, col in self.streams.items()}


def _column(name: str, spec, where: str) -> Column:
    if not isinstance(spec, dict) or 'column' not in spec or 'unit' not in spec:
        raise SourceError(f'{where}: stream {name} needs a column and a unit, e.g. '
                          f'{{column: {name}, unit: {"degC" if name == "temperature" else "rad/s"}}}')
    extra = sorted(set(spec) - {'column', 'unit'})
    if extra:
        raise SourceError(f'{where}: stream {name}: unknown key(s) {", ".join(extra)} (known: column, unit)')
    cols = spec['column']
    names = (cols,) if isinstance(cols, str) else tuple(cols) if isinstance(cols, (list, tuple)) else ()
    if not names or not all(isinstance(c, str) and c for c in names):
        raise SourceError(f'{where}: stream {name}: column must be a name or a list of names')
    if name in VECTOR_FIELDS and len(names) not in (1, 3):
        raise SourceError(f'{where}: stream {name}: give one (N, 3) variable or three columns, not {len(names)}')
    if name == 'temperature' and len(names) != 1:
        raise SourceError(f'{where}: stream temperature: give one column')
    units.conversion(name, str(spec['unit']))   # SourceError for an unknown unit
    return Column(names, str(spec['unit']))
