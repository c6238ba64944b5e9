"""UTC times as integer ns since 1970: ISO 8601 text, CF `units` attributes ('seconds since
2021-09-20 08:52:00'), and GPS week/milliseconds. Naive times are UTC."""
from __future__ import annotations

import datetime as dt
import re

import numpy as np

from .base import SourceError

_CF = re.compile(r'^\s*(\w+)\s+since\s+(.+?)\s*$')
_CF_UNITS = {'seconds': 1_000_000_000, 'second': 1_000_000_000, 's': 1_000_000_000, 'sec': 1_000_000_000,
             'milliseconds': 1_000_000, 'ms': 1_000_000, 'microseconds': 1000, 'us': 1000,
             'nanoseconds': 1, 'ns': 1, 'minutes': 60_000_000_000, 'hours': 3_600_000_000_000,
             'days': 86_400_000_000_000}
GPS_EPOCH_NS = 315_964_800 * 1_000_000_000   # 1980-01-06T00:00:00Z
GPS_LEAP_S = 18                              # GPS - UTC since 2017


def parse_utc(value, what: str = 'time') -> int:
    """ISO 8601 text or a datetime (naive = UTC) -> ns since 1970; SourceError otherwise."""
    if isinstance(value, dt.datetime):
        stamp = value
    else:
        text = str(value).strip().replace(' ', 'T', 1)
        if text.endswith('Z'):
            text = text[:-1] + '+00:00'
        try:
            stamp = dt.datetime.fromisoformat(text)
        except ValueError:
            raise SourceError(f'{what}: {value!r} is not an ISO 8601 time (e.g. 2021-09-20T09:00:00Z)') from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=dt.timezone.utc)
    delta = stamp - dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)
    return (delta.days * 86400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000


def format_utc(ns: int) -> str:
    """ns since 1970 -> '2021-09-20T09:00:00.000Z'."""
    stamp = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc) + dt.timedelta(microseconds=int(ns) // 1000)
    return stamp.strftime('%Y-%m-%dT%H:%M:%S.%f')[:-3] + 'Z'


def parse_cf_units(text: str) -> tuple[int, int] | None:
    """A CF time `units` attribute -> (ns per unit, epoch ns since 1970), or None if it is not one."""
    m = _CF.match(str(text))
    if not m or m.group(1).lower() not in _CF_UNITS:
        return None
    try:
        epoch = parse_utc(m.group(2))
    except SourceError:
        return None
    return _CF_UNITS[m.group(1).lower()], epoch


def iso_to_ns(values) -> np.ndarray:
    """ISO 8601 texts -> int64 ns since 1970 (naive = UTC); SourceError on the first that is not one."""
    out = np.empty(len(values), np.int64)
    for i, v in enumerate(values):
        out[i] = parse_utc(v, 'time column')
    return out


def gps_to_utc_ns(week: int, ms: int) -> int:
    return GPS_EPOCH_NS + (int(week) * 604800 - GPS_LEAP_S) * 1_000_000_000 + int(ms) * 1_000_000
