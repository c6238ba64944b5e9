"""PX4 ULog through pyulog: `sensor_gyro` (its `temperature` field) with `sensor_accel` of the same
instance, or `sensor_combined` where a log has no per-sensor topics; `sensor_mag` or
`vehicle_magnetometer` (gauss). PX4 publishes these in the body frame, FRD. GPS time
(`sensor_gps` / `vehicle_gps_position` `time_utc_usec`) dates the boot-time stamps when present."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import SourceError
from .flight_log import FlightLogSource, ImuCandidate

MAGIC = b'ULog\x01\x12\x35'
_TOPICS = ['sensor_gyro', 'sensor_accel', 'sensor_combined', 'sensor_mag', 'vehicle_magnetometer',
           'sensor_gps', 'vehicle_gps_position']
GAUSS_T = 1e-4


def _vec(d: dict, names: list[str]) -> np.ndarray | None:
    if not all(n in d for n in names):
        return None
    return np.column_stack([np.asarray(d[n], np.float64) for n in names])


def _stamps(d: dict) -> np.ndarray:
    t = d.get('timestamp_sample', d['timestamp'])
    return np.asarray(t, np.int64)


class ULogSource(FlightLogSource):
    kind, label = 'ulog', 'PX4 ULog'

    def __init__(self, path, imu: int | None = None):
        from pyulog import ULog
        path = Path(path)
        try:
            log = ULog(str(path), _TOPICS)
        except Exception as exc:   # pyulog raises ULogException, struct.error, IndexError for bad files
            raise SourceError(f'{path}: not a readable PX4 ULog ({type(exc).__name__}: {exc})') from None
        data = {}
        for d in log.data_list:
            data.setdefault(d.name, {})[d.multi_id] = d.data
        imus = []
        for inst, g in sorted(data.get('sensor_gyro', {}).items()):
            gyro = _vec(g, ['x', 'y', 'z'])
            acc_d = data.get('sensor_accel', {}).get(inst)
            if acc_d is not None:
                acc_t, acc = _stamps(acc_d), _vec(acc_d, ['x', 'y', 'z'])
            elif 'sensor_combined' in data:
                c = data['sensor_combined'][0]
                acc_t = np.asarray(c['timestamp'], np.int64) + np.asarray(c.get('accelerometer_timestamp_relative', 0),
                                                                          np.int64)
                acc = _vec(c, [f'accelerometer_m_s2[{k}]' for k in range(3)])
            else:
                acc = None
            if gyro is None or acc is None or not len(gyro) or not len(acc):
                continue
            temp = np.asarray(g['temperature'], np.float64) if 'temperature' in g else None
            imus.append(ImuCandidate(inst, f'sensor_gyro[{inst}]', _stamps(g), gyro, acc_t, acc,
                                     _stamps(g) if temp is not None else None, temp))
        if not imus and 'sensor_combined' in data:
            c = data['sensor_combined'][0]
            gyro = _vec(c, [f'gyro_rad[{k}]' for k in range(3)])
            acc = _vec(c, [f'accelerometer_m_s2[{k}]' for k in range(3)])
            if gyro is not None and acc is not None and len(gyro):
                t = np.asarray(c['timestamp'], np.int64)
                acc_t = t + np.asarray(c.get('accelerometer_timestamp_relative', 0), np.int64)
                temp_d = data.get('sensor_accel', {}).get(0)
                imus.append(ImuCandidate(0, 'sensor_combined', t, gyro, acc_t, acc,
                                         None if temp_d is None or 'temperature' not in temp_d else _stamps(temp_d),
                                         None if temp_d is None or 'temperature' not in temp_d
                                         else np.asarray(temp_d['temperature'], np.float64)))
        mags = []
        for inst, m in sorted(data.get('sensor_mag', {}).items()):
            field = _vec(m, ['x', 'y', 'z'])
            if field is not None and len(field):
                mags.append((f'sensor_mag[{inst}]', _stamps(m), field * GAUSS_T))
        if not mags:
            for inst, m in sorted(data.get('vehicle_magnetometer', {}).items()):
                field = _vec(m, [f'magnetometer_ga[{k}]' for k in range(3)])
                if field is not None and len(field):
                    mags.append((f'vehicle_magnetometer[{inst}]', _stamps(m), field * GAUSS_T))
        metadata = {k: v for k, v in log.msg_info_dict.items() if isinstance(v, (str, int, float))}
        metadata.update({f'param.{k}': v for k, v in log.initial_parameters.items()})
        super().__init__(path, imus, mags, imu, _utc_offset_us(data), metadata)


def _utc_offset_us(data: dict) -> int | None:
    for name in ('sensor_gps', 'vehicle_gps_position'):
        for d in data.get(name, {}).values():
            utc = np.asarray(d.get('time_utc_usec', []), np.int64)
            ok = np.flatnonzero(utc > 0)
            if ok.size:
                return int(utc[ok[0]] - np.asarray(d['timestamp'], np.int64)[ok[0]])
    return None
