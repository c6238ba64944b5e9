"""One interface for every recording: `open_source(path, ...)` returns a `Source` that yields the
package's `SensorChunk`s, whatever the format.

    from gyro_thermal_comp.sources import open_source
    with open_source('flight.ulg', imu=1) as src:          # PX4 ULog, ArduPilot .bin/.log,
        print(src.describe(), src.notes)                    # ROS 1 .bag, ROS 2 bag (any topics),
        for chunk in src.chunks(60.0): ...                  # CSV / netCDF / HDF5 with a column map

The format is recognised by content (magic bytes), never by name alone; a file that is not what it
claims is a SourceError (one line). docs/sources.md has the formats, the options and the checks.
"""
from __future__ import annotations

from pathlib import Path

from .base import DropReport, Source, SourceError
from .column_map import ColumnMap
from .timebase import parse_utc
from .topic_map import parse_topic_map

__all__ = ['ColumnMap', 'DropReport', 'KINDS', 'Source', 'SourceError', 'detect_kind', 'open_source',
           'parse_topic_map', 'resolve_window']

KINDS = {'rosbag2': 'ROS 2 bag', 'rosbag1': 'ROS 1 bag', 'ulog': 'PX4 ULog',
         'dataflash': 'ArduPilot DataFlash log', 'table': 'table (CSV, netCDF, HDF5)'}
_TABLE_SUFFIXES = ('.csv', '.tsv', '.txt', '.nc', '.nc4', '.cdf', '.h5', '.hdf5', '.hdf')
_CLAIMS = {'.ulg': 'ulog', '.bin': 'dataflash', '.bag': 'rosbag1'}


def detect_kind(path) -> str:
    """'rosbag2' | 'rosbag1' | 'ulog' | 'dataflash' | 'table', from the content; SourceError if the
    path does not exist or its content is none of them (or not what its name claims)."""
    from .dataflash import BINARY_MAGIC
    from .rosbag1 import MAGIC as ROSBAG1
    from .tabular import HDF5_MAGIC, NETCDF3_MAGIC
    from .ulog import MAGIC as ULOG
    path = Path(path)
    if not path.exists():
        raise SourceError(f'{path} does not exist')
    if path.is_dir() or path.suffix.lower() == '.mcap':
        return 'rosbag2'   # bag_io.BagReader says what is wrong with a damaged one
    try:
        with open(path, 'rb') as fh:
            head = fh.read(16)
    except OSError as exc:
        raise SourceError(f'{path}: {exc.strerror or exc}') from None
    if head.startswith(b'\x89MCAP'):
        found = 'rosbag2'
    elif head.startswith(ULOG):
        found = 'ulog'
    elif head.startswith(ROSBAG1):
        found = 'rosbag1'
    elif head.startswith(BINARY_MAGIC) or (head.startswith(b'FMT,') and path.suffix.lower() == '.log'):
        found = 'dataflash'
    elif head.startswith(HDF5_MAGIC) or head[:4] in NETCDF3_MAGIC or path.suffix.lower() in _TABLE_SUFFIXES:
        found = 'table'
    else:
        found = None
    claimed = _CLAIMS.get(path.suffix.lower())
    if claimed and found != claimed:
        raise SourceError(f'{path} is not a {KINDS[claimed]} (it starts with {head[:12]!r})')
    if found is None:
        if not head:
            raise SourceError(f'{path} is empty')
        raise SourceError(f'{path}: not a recording this package reads ({", ".join(KINDS.values())}); '
                          f'it starts with {head[:12]!r}')
    return found


def resolve_window(start=None, end=None, period: str | None = None, column_map: ColumnMap | None = None):
    """(start, end): each None, a float (s since the record's first sample) or an int (UTC ns since
    1970), from numbers, ISO 8601 texts or a column map's named period."""
    if period is not None:
        if start is not None or end is not None:
            raise SourceError('give --period or --start/--end, not both')
        periods = column_map.periods if column_map is not None else {}
        if str(period) not in periods:
            raise SourceError(f'no period {period!r} in the column map'
                              + (f' (it has: {", ".join(periods)})' if periods else ' (it names none)'))
        return periods[str(period)]
    return _when(start, '--start'), _when(end, '--end')


def _when(value, what: str):
    if value is None or isinstance(value, (int, float)) and not isinstance(value, bool):
        return None if value is None else float(value)
    text = str(value).strip()
    try:
        return float(text)
    except ValueError:
        return parse_utc(text, what)


def open_source(path, *, topic_map=None, column_map=None, imu: int | None = None, start=None, end=None,
                period: str | None = None) -> Source:
    """The `Source` for `path` (detect_kind). `topic_map`: ROS bags' streams by topic ({'imu':
    '/my_imu/data_raw'} or ['imu=/my_imu/data_raw']). `column_map`: a ColumnMap, a dict or a YAML
    path, for tables. `imu`: the IMU instance of a flight log. `start`/`end`: s since the record's
    first sample (numbers) or UTC (ISO 8601 text); `period`: a name from the column map's periods.
    Options a format does not use are an error, not ignored."""
    kind = detect_kind(path)
    tmap = parse_topic_map(topic_map)
    if tmap and kind not in ('rosbag1', 'rosbag2'):
        raise SourceError(f'{path}: --topic maps the topics of ROS bags; this is a {KINDS[kind]}')
    if column_map is not None and kind != 'table':
        raise SourceError(f'{path}: a column map is for tables (CSV, netCDF, HDF5); this is a {KINDS[kind]}')
    if isinstance(column_map, (str, Path)):
        column_map = ColumnMap.load(column_map)
    elif isinstance(column_map, dict):
        column_map = ColumnMap.from_dict(column_map)
    if imu is not None and kind not in ('ulog', 'dataflash'):
        raise SourceError(f'{path}: --imu picks an IMU of a flight log; this is a {KINDS[kind]}')
    lo, hi = resolve_window(start, end, period, column_map)
    if kind == 'table':
        if column_map is None:
            raise SourceError(f'{path}: a table needs a column map (--map FILE: names, units, axes, rate; '
                              'docs/sources.md, config/import/cats.yaml)')
        from .tabular import TableSource
        source = TableSource(path, column_map)
        if isinstance(lo, int) or isinstance(hi, int):
            if isinstance(lo, float) or isinstance(hi, float):
                first = source.first_stamp_ns()
                lo, hi = (first + int(round(v * 1e9)) if isinstance(v, float) else v for v in (lo, hi))
            return source.select_utc(lo, hi)
        return source.select(lo, hi) if lo is not None or hi is not None else source
    if kind == 'rosbag2':
        from .rosbag2 import Rosbag2Source
        source = Rosbag2Source(path, tmap)
    elif kind == 'rosbag1':
        from .rosbag1 import Rosbag1Source
        source = Rosbag1Source(path, tmap)
    elif kind == 'ulog':
        from .ulog import ULogSource
        source = ULogSource(path, imu)
    else:
        from .dataflash import DataFlashSource
        source = DataFlashSource(path, imu)
    if lo is None and hi is None:
        return source
    first_s = source.span_s()[0]
    rel = [None if v is None else first_s + v if isinstance(v, float) else (v - source.time_origin_ns) * 1e-9
           for v in (lo, hi)]
    source.select(*rel)
    if rel[0] is not None and rel[1] is not None and rel[1] <= rel[0]:
        raise SourceError(f'{path}: the time window ends before it starts')
    return source
