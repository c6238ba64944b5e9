"""Tables of samples: CSV (numpy), netCDF4 and HDF5 (h5py), netCDF3 (scipy), through a column map.

Rows are samples at the time column's stamps (or at `rate_hz`). A time window is found by bisection
on the time column and only its rows are read: a long record's other parts are never loaded. Units
and axes come from the column map and are checked against the file's own `units` and `axes`
attributes where it has them (a mismatch is an error, not a guess); the values, after conversion,
must be physically possible (checks.py).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..samples import ImuSamples, MagSamples, TemperatureSamples
from . import checks, frames, units
from .base import ArraySource, SourceError
from .cleaning import clean
from .column_map import VECTOR_FIELDS, ColumnMap
from .timebase import format_utc, iso_to_ns, parse_cf_units

HDF5_MAGIC = b'\x89HDF\r\n\x1a\n'
NETCDF3_MAGIC = (b'CDF\x01', b'CDF\x02', b'CDF\x05')
RATE_TOLERANCE = 0.05   # declared rate_hz vs the stamps' median rate


def _text(value) -> str | None:
    if value is None:
        return None
    if isinstance(value, (bytes, np.bytes_)):
        return value.decode('utf-8', 'replace')
    if isinstance(value, np.ndarray) and value.size == 1:
        return _text(value.reshape(-1)[0])
    return str(value)


class _Hdf5Table:
    """netCDF4 / HDF5 variables through h5py (read lazily, by row range)."""
    kind = 'netCDF4/HDF5'

    def __init__(self, path: Path):
        import h5py
        try:
            self._f = h5py.File(path, 'r')
        except OSError as exc:
            raise SourceError(f'{path}: not a readable netCDF4/HDF5 file ({exc})') from None
        self.attrs = {k: _text(v) for k, v in self._f.attrs.items()}

    def has(self, name: str) -> bool:
        return name in self._f and hasattr(self._f[name], 'shape')

    def names(self) -> list[str]:
        out = []
        self._f.visititems(lambda n, obj: out.append(n) if hasattr(obj, 'shape') else None)
        return out

    def attr(self, name: str, key: str) -> str | None:
        return _text(self._f[name].attrs.get(key))

    def shape(self, name: str) -> tuple:
        return self._f[name].shape

    def read(self, name: str, start: int, stop: int, rows_axis: int = 0) -> np.ndarray:
        ds = self._f[name]
        data = ds[start:stop] if rows_axis == 0 else ds[:, start:stop].T
        return np.asarray(data)

    def close(self):
        self._f.close()


class _Netcdf3Table:
    """netCDF3 classic / 64-bit offset files through scipy."""
    kind = 'netCDF3'

    def __init__(self, path: Path):
        from scipy.io import netcdf_file
        try:
            self._f = netcdf_file(path, 'r', mmap=False)
        except Exception as exc:   # scipy raises TypeError/ValueError for files it cannot parse
            raise SourceError(f'{path}: not a readable netCDF3 file ({exc})') from None
        self.attrs = {k: _text(v) for k, v in self._f._attributes.items()}

    def has(self, name: str) -> bool:
        return name in self._f.variables

    def names(self) -> list[str]:
        return list(self._f.variables)

    def attr(self, name: str, key: str) -> str | None:
        return _text(self._f.variables[name]._attributes.get(key))

    def shape(self, name: str) -> tuple:
        return self._f.variables[name].shape

    def read(self, name: str, start: int, stop: int, rows_axis: int = 0) -> np.ndarray:
        v = self._f.variables[name]
        return np.array(v[start:stop] if rows_axis == 0 else v[:, start:stop].T)

    def close(self):
        self._f.close()


class _CsvTable:
    """A CSV (or ';' / tab separated) file with one header row; read whole when opened."""
    kind = 'CSV'

    def __init__(self, path: Path, wanted: list[str], text_columns: set[str]):
        try:
            with open(path, newline='') as fh:
                head = fh.readline()
                sample = head + fh.read(4096)
        except (OSError, UnicodeDecodeError) as exc:
            raise SourceError(f'{path}: not a readable text table ({exc})') from None
        if not head.strip():
            raise SourceError(f'{path}: empty file, expected a CSV header row')
        try:
            delimiter = csv.Sniffer().sniff(sample, delimiters=',;\t').delimiter
        except csv.Error:
            delimiter = ','
        header = [h.strip() for h in next(csv.reader([head], delimiter=delimiter))]
        self.attrs = {}
        self._header = header
        missing = [w for w in wanted if w not in header]
        if missing:
            raise SourceError(f'{path}: no column(s) {", ".join(missing)} (the header has: {", ".join(header)})')
        self._data = {}
        for name in wanted:
            idx = header.index(name)
            dtype = str if name in text_columns else float
            try:
                col = np.genfromtxt(path, delimiter=delimiter, skip_header=1, usecols=(idx,), dtype=dtype,
                                    encoding='utf-8', autostrip=True, invalid_raise=False, ndmin=1)
            except ValueError as exc:
                raise SourceError(f'{path}: column {name}: {exc}') from None
            self._data[name] = np.atleast_1d(col)
        lengths = {len(v) for v in self._data.values()}
        if len(lengths) > 1:
            raise SourceError(f'{path}: rows of different lengths (columns give {sorted(lengths)} values)')

    def has(self, name: str) -> bool:
        return name in self._data

    def names(self) -> list[str]:
        return list(self._header)

    def attr(self, name: str, key: str) -> str | None:
        return None

    def shape(self, name: str) -> tuple:
        return self._data[name].shape

    def read(self, name: str, start: int, stop: int, rows_axis: int = 0) -> np.ndarray:
        return self._data[name][start:stop]

    def close(self):
        pass


def open_table(path: Path, column_map: ColumnMap):
    """The container for `path` by its first bytes (HDF5, netCDF3) or as CSV text."""
    with open(path, 'rb') as fh:
        head = fh.read(8)
    if head.startswith(HDF5_MAGIC):
        return _Hdf5Table(path)
    if head[:4] in NETCDF3_MAGIC:
        return _Netcdf3Table(path)
    if path.suffix.lower() in ('.nc', '.h5', '.hdf5', '.hdf', '.nc4', '.cdf'):
        raise SourceError(f'{path}: not a netCDF or HDF5 file (it starts with {head[:8]!r})')
    wanted = [c for col in column_map.streams.values() for c in col.names]
    text = set()
    if column_map.time_column:
        wanted.append(column_map.time_column)
        if column_map.time_unit == 'iso8601':
            text.add(column_map.time_column)
    if b'\x00' in head:
        raise SourceError(f'{path}: a binary file that is not netCDF or HDF5; tables are CSV, netCDF or HDF5')
    return _CsvTable(path, list(dict.fromkeys(wanted)), text)


class TableSource(ArraySource):
    """A table read through a `ColumnMap` into imu, mag and temperature streams (FLU, SI)."""
    kind = 'table'

    def __init__(self, path, column_map: ColumnMap):
        super().__init__(path)
        self.map = column_map
        self.table = open_table(self.path, column_map)
        self.label = self.table.kind
        self.metadata = {k: v for k, v in self.table.attrs.items() if v is not None}
        self._window_ns: tuple[int | None, int | None] = (None, None)
        self._rows = self._row_layout()
        self._loaded = False

    def close(self) -> None:
        self.table.close()

    # ------------------------------------------------------------------ layout
    def _need(self, name: str) -> None:
        if not self.table.has(name):
            raise SourceError(f'{self.path}: no variable/column {name!r} (it has: {", ".join(self.table.names())})')

    def _row_layout(self) -> dict:
        """name -> rows axis (0, or 1 for a (3, N) variable); checks every column exists and that
        they all have one length."""
        layout, length = {}, None
        names = [c for col in self.map.streams.values() for c in col.names]
        if self.map.time_column:
            names.append(self.map.time_column)
        for name in dict.fromkeys(names):
            self._need(name)
            shape = self.table.shape(name)
            axis = 1 if len(shape) == 2 and shape[0] == 3 and shape[1] != 3 else 0
            n = shape[axis] if shape else 0
            if length is not None and n != length:
                raise SourceError(f'{self.path}: {name} has {n} rows, other columns {length}')
            layout[name], length = axis, n
        self.n_rows = int(length or 0)
        if not self.n_rows:
            raise SourceError(f'{self.path}: no rows')
        return layout

    def _read(self, name: str, lo: int, hi: int) -> np.ndarray:
        return self.table.read(name, lo, hi, self._rows[name])

    # ------------------------------------------------------------------ time
    def _time_scale(self) -> tuple[int | None, int]:
        """(ns per unit of the time column, epoch ns); (None, epoch) for ISO text."""
        m = self.map
        if m.time_unit == 'iso8601':
            return None, 0
        cf = parse_cf_units(self.table.attr(m.time_column, 'units') or '')
        if m.time_unit is not None:
            scale = int(round(units.conversion('time', m.time_unit)[0] * 1e9))
            if cf is not None and cf[0] != scale:
                raise SourceError(f'{self.path}: column map says time in {m.time_unit}, the file\'s '
                                  f'{m.time_column} says {self.table.attr(m.time_column, "units")!r}')
        elif cf is not None:
            scale = cf[0]
        else:
            raise SourceError(f'column map: time column {m.time_column} has no unit (time.unit: s, ms, us, ns '
                              'or iso8601) and the file gives none')
        epoch = m.epoch_ns if m.epoch_ns is not None else (cf[1] if cf is not None else 0)
        return scale, epoch

    def _stamps_ns(self, lo: int, hi: int) -> np.ndarray:
        m = self.map
        if m.time_column is None:
            k = np.arange(lo, hi, dtype=np.float64)
            return (m.epoch_ns or 0) + np.rint(k * 1e9 / m.rate_hz).astype(np.int64)
        raw = self._read(m.time_column, lo, hi)
        scale, epoch = self._time_scale()
        if scale is None:
            return iso_to_ns([str(v) for v in raw])
        raw = np.asarray(raw, dtype=np.float64)
        out = np.full(raw.shape, np.iinfo(np.int64).min, np.int64)
        ok = np.isfinite(raw)
        out[ok] = epoch + np.rint(raw[ok] * scale).astype(np.int64)
        return out

    def _row_at(self, target_ns: int) -> int:
        """First row whose stamp is >= target (bisection, a few reads; stamps must not decrease)."""
        lo, hi = 0, self.n_rows
        while lo < hi:
            mid = (lo + hi) // 2
            if self._stamps_ns(mid, mid + 1)[0] < target_ns:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def first_stamp_ns(self) -> int:
        return int(self._stamps_ns(0, 1)[0])

    # ------------------------------------------------------------------ window
    def select_utc(self, start_ns: int | None, end_ns: int | None) -> 'TableSource':
        self._window_ns = (start_ns, end_ns)
        self._loaded = False
        self.streams = {}
        return self

    def select(self, start_s=None, end_s=None) -> 'TableSource':
        first = self.first_stamp_ns()
        return self.select_utc(None if start_s is None else first + int(round(start_s * 1e9)),
                               None if end_s is None else first + int(round(end_s * 1e9)))

    def _load(self) -> None:
        if self._loaded:
            return
        lo_ns, hi_ns = self._window_ns
        lo = 0 if lo_ns is None else self._row_at(lo_ns)
        hi = self.n_rows if hi_ns is None else self._row_at(hi_ns)
        if hi <= lo:
            raise SourceError(f'{self.path}: no rows between {format_utc(lo_ns or 0)} and {format_utc(hi_ns or 0)}')
        t_ns = self._stamps_ns(lo, hi)
        good_t = t_ns != np.iinfo(np.int64).min
        self.dropped.add('time', 'not finite', int((~good_t).sum()))
        if not good_t.any():
            raise SourceError(f'{self.path}: no finite time stamps in the rows read')
        self.time_origin_ns = int(t_ns[good_t][0])
        t = (t_ns - self.time_origin_ns) * 1e-9
        t[~good_t] = np.nan
        self._check_rate(t[good_t])
        values = {name: self._convert(name, lo, hi) for name in self.map.streams}
        self._to_streams(t, values)
        self._loaded = True
        self.notes.append(f'rows {lo}..{hi - 1} of {self.n_rows}: {format_utc(self.time_origin_ns)} to '
                          f'{format_utc(self.time_origin_ns + int(np.nanmax(t) * 1e9))}')

    def _check_rate(self, t: np.ndarray) -> None:
        if self.map.rate_hz is None or self.map.time_column is None or len(t) < 3:
            return
        dt = np.diff(t)
        dt = dt[dt > 0]
        if not dt.size:
            return
        measured = 1.0 / float(np.median(dt))
        if abs(measured / self.map.rate_hz - 1.0) > RATE_TOLERANCE:
            raise SourceError(f'{self.path}: column map declares rate_hz {self.map.rate_hz:g}, the time column gives '
                              f'{measured:.4g} Hz: is the time unit right?')

    def _convert(self, name: str, lo: int, hi: int) -> np.ndarray:
        col = self.map.streams[name]
        for c in col.names:   # the file's own unit attribute must agree with the map
            said = self.table.attr(c, 'units')
            if said and units.lookup(units.QUANTITY[name], said) is not None and not units.same_unit(name, said, col.unit):
                raise SourceError(f'{self.path}: column map says {name} in {col.unit}, the file\'s {c} says {said!r}')
        parts = [np.asarray(self._read(c, lo, hi), dtype=np.float64) for c in col.names]
        data = parts[0] if len(parts) == 1 else np.column_stack(parts)
        if name in VECTOR_FIELDS and (data.ndim != 2 or data.shape[1] != 3):
            raise SourceError(f'{self.path}: {name} column {col.names[0]} has shape {data.shape}, expected (N, 3)')
        if name == 'temperature' and data.ndim != 1:
            raise SourceError(f'{self.path}: temperature column {col.names[0]} has shape {data.shape}, expected (N,)')
        scale, offset = units.conversion(name, col.unit)
        return data * scale + offset

    def _axes(self) -> np.ndarray:
        said = {self.table.attr(c, 'axes') for f in VECTOR_FIELDS if f in self.map.streams
                for c in self.map.streams[f].names[:1]} - {None}
        declared = self.map.axes
        if declared is not None and said and any(s.upper() != declared.upper() for s in said):
            raise SourceError(f'{self.path}: column map says axes {declared}, the file says {", ".join(sorted(said))}')
        if declared is None and len(said) > 1:
            raise SourceError(f'{self.path}: the file gives different axes per variable ({", ".join(sorted(said))}): '
                              'declare `axes` in the column map')
        axes = declared or (said.pop() if said else 'FLU')
        origin = 'column map' if declared else ('file attribute' if axes != 'FLU' or said else 'default')
        E = frames.axes_matrix(axes)
        if axes.upper() != 'FLU':
            mirrored = frames.is_left_handed(E)
            self.notes.append(f'axes {axes.upper()} ({origin}{", left-handed" if mirrored else ""}) -> FLU'
                              + (f'; gyro as {self.map.gyro_transform}' if mirrored else ''))
        self.axes_convention = axes.upper()
        return E

    def _to_streams(self, t: np.ndarray, values: dict) -> None:
        E = self._axes()
        G = frames.gyro_matrix(E, self.map.gyro_transform)
        imu = ImuSamples(t, frames.rotate_rows(G, values['gyro']), frames.rotate_rows(E, values['accel']))
        mag = MagSamples(t, frames.rotate_rows(E, values['mag'])) if 'mag' in values else None
        temp = TemperatureSamples(t, values['temperature']) if 'temperature' in values else None
        imu, mag, temp = (clean(n, s, self.dropped) for n, s in (('imu', imu), ('mag', mag), ('temperature', temp)))
        if imu is None:
            raise SourceError(f'{self.path}: no row with finite gyro and accelerometer values')
        checks.check_streams(imu, mag, temp, self.map.declared_units(), str(self.path))
        self.streams = {'imu': imu, 'mag': mag, 'temperature': temp}
        self.origins = {'imu': f'{self.map.streams["gyro"].names[0]} + {self.map.streams["accel"].names[0]}',
                        **{n: self.map.streams[f].names[0] for n, f in (('mag', 'mag'), ('temperature', 'temperature'))
                           if f in self.map.streams}}

    # ------------------------------------------------------------------ Source
    def streams_present(self) -> dict[str, str]:
        self._load()
        return super().streams_present()

    def span_s(self) -> tuple[float, float]:
        self._load()
        return super().span_s()

    def rate_hz(self, stream: str) -> float | None:
        self._load()
        return super().rate_hz(stream)

    def _chunks(self, chunk_s, streams):
        self._load()
        return super()._chunks(chunk_s, streams)
