"""ArduPilot DataFlash logs (binary .bin, or text .log) through pymavlink: `IMU` (rad/s, m/s^2, its
`T` field in degC) per instance (`I` field, or the older IMU2/IMU3 messages), `MAG` (milligauss)
likewise, all in the body frame FRD. `TimeUS` is time since boot; the first GPS fix
(`GWk`, `GMS`) dates it. Parameters (`PARM`) go into the metadata as `param.NAME`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import SourceError
from .flight_log import FlightLogSource, ImuCandidate
from .timebase import gps_to_utc_ns

BINARY_MAGIC = b'\xa3\x95\x80'    # a DataFlash file opens with the FMT message's FMT
MILLIGAUSS_T = 1e-7
_IMU_TYPES = {'IMU': 0, 'IMU2': 1, 'IMU3': 2}
_MAG_TYPES = {'MAG': 0, 'MAG2': 1, 'MAG3': 2}


def _instance(m, default: int) -> int:
    try:
        return int(m.I)
    except AttributeError:
        return default


class DataFlashSource(FlightLogSource):
    kind, label = 'dataflash', 'ArduPilot DataFlash log'

    def __init__(self, path, imu: int | None = None):
        from pymavlink.DFReader import DFReader_binary, DFReader_text
        path = Path(path)
        with open(path, 'rb') as fh:
            head = fh.read(4)
        reader_cls = DFReader_binary if head.startswith(BINARY_MAGIC) else DFReader_text
        try:
            log = reader_cls(str(path), zero_time_base=True)
        except Exception as exc:   # pymavlink raises many types on foreign files
            raise SourceError(f'{path}: not a readable ArduPilot DataFlash log ({type(exc).__name__}: {exc})') from None
        imu_rows: dict[int, list] = {}
        mag_rows: dict[int, list] = {}
        params, gps = {}, None
        wanted = list(_IMU_TYPES) + list(_MAG_TYPES) + ['PARM', 'GPS']
        try:
            while True:
                m = log.recv_match(type=wanted)
                if m is None:
                    break
                kind = m.get_type()
                if kind in _IMU_TYPES:
                    temp = getattr(m, 'T', None) if 'T' in m.fmt.colhash else None
                    imu_rows.setdefault(_instance(m, _IMU_TYPES[kind]), []).append(
                        (m.TimeUS, m.GyrX, m.GyrY, m.GyrZ, m.AccX, m.AccY, m.AccZ,
                         np.nan if temp is None else temp))
                elif kind in _MAG_TYPES:
                    mag_rows.setdefault(_instance(m, _MAG_TYPES[kind]), []).append((m.TimeUS, m.MagX, m.MagY, m.MagZ))
                elif kind == 'PARM':
                    params[f'param.{m.Name}'] = float(m.Value)
                elif kind == 'GPS' and gps is None and 'GWk' in m.fmt.colhash and m.GWk > 0 \
                        and getattr(m, 'Status', 3) >= 3:
                    gps = int(gps_to_utc_ns(m.GWk, m.GMS) // 1000) - int(m.TimeUS)
        except Exception as exc:   # a log cut mid-message, a field a message lacks
            if not imu_rows:
                raise SourceError(f'{path}: not a readable ArduPilot DataFlash log ({type(exc).__name__}: {exc})') \
                    from None
            damaged = f'log read up to a damaged message ({type(exc).__name__})'
        else:
            damaged = None
        imus = []
        for inst, rows in sorted(imu_rows.items()):
            a = np.asarray(rows, np.float64)
            t = a[:, 0].astype(np.int64)
            has_t = np.isfinite(a[:, 7]).any()
            imus.append(ImuCandidate(inst, f'IMU {inst}', t, a[:, 1:4], t, a[:, 4:7],
                                     t if has_t else None, a[:, 7] if has_t else None))
        mags = []
        for inst, rows in sorted(mag_rows.items()):
            a = np.asarray(rows, np.float64)
            mags.append((f'MAG {inst}', a[:, 0].astype(np.int64), a[:, 1:4] * MILLIGAUSS_T))
        if not imus:
            raise SourceError(f'{path}: an ArduPilot DataFlash log without IMU messages')
        super().__init__(path, imus, mags, imu, gps, params)
        if damaged:
            self.notes.append(damaged)
