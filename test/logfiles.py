"""Small recordings in other programs' formats, written by the tests from a simulated unit: a PX4 ULog
(the ULog file format: header, definitions, data messages), an ArduPilot DataFlash .bin (FMT-described
binary messages), a ROS 1 bag (rosbags' writer), and CATS-shaped tables (netCDF4 through h5py,
netCDF3 through scipy, CSV). Each writer converts the simulated FLU/SI streams into the format's own
axes and units, so reading them back must give the simulated values again."""
from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from gyro_thermal_comp import sim
from gyro_thermal_comp.samples import concat_chunks

FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])   # a proper rotation: vectors and the gyro alike
EPOCH_UTC_NS = sim.EPOCH_NS
CATS_EPOCH = '2021-09-20 08:52:00'
CATS_EPOCH_NS = 1632127920 * 1_000_000_000


@dataclass(frozen=True)
class Record:
    """A simulated unit at rest (FLU, SI, t in s from 0)."""
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag_t: np.ndarray
    mag: np.ndarray
    temp_t: np.ndarray
    temp_c: np.ndarray


@lru_cache(maxsize=4)
def simulated(duration_s: float = 1200.0, imu_hz: float = 20.0, seed: int = 11) -> Record:
    """static_ramp compressed into `duration_s` by a hotter oven (23 -> ~46 degC in 20 min)."""
    cfg = sim.make_config('static_ramp', seed=seed, duration_s=duration_s, imu_rate_hz=imu_hz, mag_rate_hz=10.0,
                          temp_rate_hz=1.0, truth_rate_hz=1.0, params={'temp_peak_c': 100.0})
    c = concat_chunks(sim.simulate(cfg))
    return Record(c.imu.t, c.imu.gyro, c.imu.accel, c.mag.t, c.mag.field, c.temperature.t, c.temperature.temp_c)


# ---------------------------------------------------------------- PX4 ULog
_ULOG_TYPES = {'uint64_t': 'Q', 'uint32_t': 'I', 'uint8_t': 'B', 'float': 'f', 'int32_t': 'i'}


def _ulog_msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack('<HB', len(payload), kind[0]) + payload


def write_ulog(path, rec: Record, *, n_imus: int = 2, boot_us: int = 5_000_000, temp_offsets=(0.0, 4.0),
               with_gps: bool = True) -> None:
    """sensor_gyro/sensor_accel (multi-instance), sensor_mag (gauss), sensor_gps; FRD, us since boot.
    IMU k reads the same motion, its temperature offset by temp_offsets[k]."""
    formats = {
        'sensor_gyro': [('uint64_t', 'timestamp'), ('uint64_t', 'timestamp_sample'), ('uint32_t', 'device_id'),
                        ('float', 'x'), ('float', 'y'), ('float', 'z'), ('float', 'temperature'),
                        ('uint32_t', 'error_count')],
        'sensor_accel': [('uint64_t', 'timestamp'), ('uint64_t', 'timestamp_sample'), ('uint32_t', 'device_id'),
                         ('float', 'x'), ('float', 'y'), ('float', 'z'), ('float', 'temperature'),
                         ('uint32_t', 'error_count')],
        'sensor_mag': [('uint64_t', 'timestamp'), ('uint64_t', 'timestamp_sample'), ('uint32_t', 'device_id'),
                       ('float', 'x'), ('float', 'y'), ('float', 'z'), ('float', 'temperature')],
        'sensor_gps': [('uint64_t', 'timestamp'), ('uint64_t', 'time_utc_usec'), ('int32_t', 'lat')],
    }
    out = bytearray(b'ULog\x01\x12\x35' + bytes([1]) + struct.pack('<Q', boot_us))
    out += _ulog_msg(b'B', bytes(16) + struct.pack('<3Q', 0, 0, 0))
    for name, fields in formats.items():
        out += _ulog_msg(b'F', (name + ':' + ''.join(f'{t} {n};' for t, n in fields)).encode())
    key = b'char[4] sys_name'
    out += _ulog_msg(b'I', bytes([len(key)]) + key + b'PX4\x00')
    key = b'char[8] sys_uuid'
    out += _ulog_msg(b'I', bytes([len(key)]) + key + b'UNIT0042')
    ids = {}
    for name in formats:
        for inst in range(n_imus if name in ('sensor_gyro', 'sensor_accel') else 1):
            if name == 'sensor_gps' and not with_gps:
                continue
            ids[(name, inst)] = len(ids)
            out += _ulog_msg(b'A', struct.pack('<BH', inst, ids[(name, inst)]) + name.encode())
    t_us = boot_us + np.rint(rec.t * 1e6).astype(np.int64)
    gyro, accel = rec.gyro @ FLU_TO_FRD.T, rec.accel @ FLU_TO_FRD.T
    temp = np.interp(rec.t, rec.temp_t, rec.temp_c)
    records = []   # (time us, bytes)
    for inst in range(n_imus):
        fmt_g = '<' + ''.join(_ULOG_TYPES[t] for t, _ in formats['sensor_gyro'])
        for k in range(len(t_us)):
            tu = int(t_us[k])
            tc = float(temp[k] + temp_offsets[inst])
            records.append((tu, _ulog_msg(b'D', struct.pack('<H', ids[('sensor_gyro', inst)]) + struct.pack(
                fmt_g, tu, tu, 100 + inst, *gyro[k], tc, 0))))
            records.append((tu, _ulog_msg(b'D', struct.pack('<H', ids[('sensor_accel', inst)]) + struct.pack(
                fmt_g, tu, tu, 200 + inst, *accel[k], tc, 0))))
    m_us = boot_us + np.rint(rec.mag_t * 1e6).astype(np.int64)
    fmt_m = '<' + ''.join(_ULOG_TYPES[t] for t, _ in formats['sensor_mag'])
    field = rec.mag @ FLU_TO_FRD.T / 1e-4
    for k in range(len(m_us)):
        tu = int(m_us[k])
        records.append((tu, _ulog_msg(b'D', struct.pack('<H', ids[('sensor_mag', 0)]) + struct.pack(
            fmt_m, tu, tu, 300, *field[k], 30.0))))
    if with_gps:
        tu = int(t_us[len(t_us) // 2])
        utc_us = EPOCH_UTC_NS // 1000 + int(rec.t[len(t_us) // 2] * 1e6)
        records.append((tu, _ulog_msg(b'D', struct.pack('<H', ids[('sensor_gps', 0)]) + struct.pack('<QQi', tu, utc_us, 0))))
    records.sort(key=lambda r: r[0])
    out += b''.join(r[1] for r in records)
    with open(path, 'wb') as fh:
        fh.write(out)


# ---------------------------------------------------------------- ArduPilot DataFlash
def _df(msg_type: int, payload: bytes) -> bytes:
    return b'\xa3\x95' + bytes([msg_type]) + payload


def _fmt(msg_type: int, name: str, fmt: str, columns: str, struct_fmt: str) -> bytes:
    length = 3 + struct.calcsize('<' + struct_fmt)
    return _df(0x80, struct.pack('<BB4s16s64s', msg_type, length, name.encode(), fmt.encode(), columns.encode()))


def write_dataflash(path, rec: Record, *, n_imus: int = 2, boot_us: int = 3_000_000, temp_offsets=(0.0, 6.0),
                    with_gps: bool = True) -> None:
    """IMU (with I and T) per instance, MAG (milligauss, int16), PARM, GPS; FRD; TimeUS since boot."""
    imu_s, mag_s, parm_s, gps_s = 'QBffffffIIfBBHH', 'QBhhhhhhhhhBI', 'Q16sf', 'QBBIH'
    out = bytearray(_fmt(0x80, 'FMT', 'BBnNZ', 'Type,Length,Name,Format,Columns', 'BB4s16s64s'))
    out += _fmt(130, 'IMU', 'QBffffffIIfBBHH', 'TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz', imu_s)
    out += _fmt(131, 'MAG', 'QBhhhhhhhhhBI', 'TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOX,MOY,MOZ,Health,S', mag_s)
    out += _fmt(132, 'PARM', 'QNf', 'TimeUS,Name,Value', parm_s)
    out += _fmt(133, 'GPS', 'QBBIH', 'TimeUS,I,Status,GMS,GWk', gps_s)
    out += _df(132, struct.pack('<' + parm_s, boot_us, b'INS_GYR_ID', 2752522.0))
    t_us = boot_us + np.rint(rec.t * 1e6).astype(np.int64)
    gyro, accel = rec.gyro @ FLU_TO_FRD.T, rec.accel @ FLU_TO_FRD.T
    temp = np.interp(rec.t, rec.temp_t, rec.temp_c)
    records = []
    for k in range(len(t_us)):
        for inst in range(n_imus):
            records.append((int(t_us[k]), _df(130, struct.pack('<' + imu_s, int(t_us[k]), inst, *gyro[k], *accel[k],
                                                               0, 0, float(temp[k] + temp_offsets[inst]), 1, 1,
                                                               int(1 / (rec.t[1] - rec.t[0])), 0))))
    m_us = boot_us + np.rint(rec.mag_t * 1e6).astype(np.int64)
    field = np.rint(rec.mag @ FLU_TO_FRD.T / 1e-7).astype(int)
    for k in range(len(m_us)):
        records.append((int(m_us[k]), _df(131, struct.pack('<' + mag_s, int(m_us[k]), 0, *field[k], 0, 0, 0, 0, 0, 0,
                                                           1, 0))))
    if with_gps:
        k = len(t_us) // 2
        gps_ns = EPOCH_UTC_NS + int(rec.t[k] * 1e9) - 315964800 * 10 ** 9 + 18 * 10 ** 9
        week, rem = divmod(gps_ns // 10 ** 6, 604800 * 1000)
        records.append((int(t_us[k]), _df(133, struct.pack('<' + gps_s, int(t_us[k]), 0, 3, int(rem), int(week)))))
    records.sort(key=lambda r: r[0])
    out += b''.join(r[1] for r in records)
    with open(path, 'wb') as fh:
        fh.write(out)


# ---------------------------------------------------------------- ROS 1 bag
def write_rosbag1(path, rec: Record, topics=None) -> None:
    """sensor_msgs/Imu, MagneticField, Temperature (REP 103 frame), stamped from the simulator epoch."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    topics = topics or {'imu': '/imu/data_raw', 'mag': '/imu/mag', 'temperature': '/imu/temperature'}
    Header, Time, Vec3, Quat = (T['std_msgs/msg/Header'], T['builtin_interfaces/msg/Time'],
                                T['geometry_msgs/msg/Vector3'], T['geometry_msgs/msg/Quaternion'])

    def header(t_s, seq):
        ns = EPOCH_UTC_NS + int(round(t_s * 1e9))
        return Header(seq=seq, stamp=Time(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), frame_id='imu_link'), ns
    z9 = np.zeros(9)
    items = []
    for k, t in enumerate(rec.t.tolist()):
        h, ns = header(t, k)
        msg = T['sensor_msgs/msg/Imu'](header=h, orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
                                       orientation_covariance=np.r_[-1.0, np.zeros(8)],
                                       angular_velocity=Vec3(x=rec.gyro[k, 0], y=rec.gyro[k, 1], z=rec.gyro[k, 2]),
                                       angular_velocity_covariance=z9,
                                       linear_acceleration=Vec3(x=rec.accel[k, 0], y=rec.accel[k, 1], z=rec.accel[k, 2]),
                                       linear_acceleration_covariance=z9)
        items.append((ns, 'imu', msg, 'sensor_msgs/msg/Imu'))
    for k, t in enumerate(rec.mag_t.tolist()):
        h, ns = header(t, k)
        items.append((ns, 'mag', T['sensor_msgs/msg/MagneticField'](
            header=h, magnetic_field=Vec3(x=rec.mag[k, 0], y=rec.mag[k, 1], z=rec.mag[k, 2]),
            magnetic_field_covariance=z9), 'sensor_msgs/msg/MagneticField'))
    for k, t in enumerate(rec.temp_t.tolist()):
        h, ns = header(t, k)
        items.append((ns, 'temperature', T['sensor_msgs/msg/Temperature'](header=h, temperature=float(rec.temp_c[k]),
                                                                          variance=0.0), 'sensor_msgs/msg/Temperature'))
    items.sort(key=lambda x: x[0])
    with Writer(path) as writer:
        conns = {name: writer.add_connection(topics[name], msgtype, typestore=ts)
                 for name, msgtype in (('imu', 'sensor_msgs/msg/Imu'), ('mag', 'sensor_msgs/msg/MagneticField'),
                                       ('temperature', 'sensor_msgs/msg/Temperature'))}
        for ns, name, msg, msgtype in items:
            writer.write(conns[name], ns, ts.serialize_ros1(msg, msgtype))


# ---------------------------------------------------------------- CATS-shaped tables
FLU_TO_FRU = np.diag([1.0, -1.0, 1.0])    # a mirror
UPSIDE_DOWN = np.diag([1.0, -1.0, -1.0])  # half a turn about x: how the CATS tag lay in its first period


def cats_arrays(rec: Record, rotation=UPSIDE_DOWN) -> dict:
    """1 Hz point samples as the CATS tag logs them: FRU axes, gyro mrad/s (axial: it follows the
    mirror with a sign), accel m/s^2, field uT, temperature degC, stamps in integer s."""
    step = int(round(1.0 / (rec.t[1] - rec.t[0])))
    k = np.arange(0, len(rec.t), step)
    gyro, accel = rec.gyro[k] @ rotation.T, rec.accel[k] @ rotation.T
    field = np.column_stack([np.interp(rec.t[k], rec.mag_t, rec.mag[:, j]) for j in range(3)]) @ rotation.T
    return {'timestamp_utc': np.rint(rec.t[k]).astype(np.int64) + 480,
            'angular_velocity': -(gyro @ FLU_TO_FRU.T) * 1e3,
            'acceleration': accel @ FLU_TO_FRU.T,
            'magnetic_density': field @ FLU_TO_FRU.T * 1e6,
            'temperature': np.round(np.interp(rec.t[k], rec.temp_t, rec.temp_c), 2)}


CATS_UNITS = {'angular_velocity': 'mrad/s', 'acceleration': 'm/s2', 'magnetic_density': 'uT', 'temperature': 'C'}


def write_cats_netcdf4(path, arrays: dict, axes: str = 'FRU') -> None:
    import h5py
    with h5py.File(path, 'w') as f:
        f.attrs['history'] = 'written by the gyro_thermal_comp tests in the shape of the CATS calibration file'
        ts = f.create_dataset('timestamp_utc', data=arrays['timestamp_utc'])
        ts.attrs['units'] = f'seconds since {CATS_EPOCH}'
        ts.make_scale('timestamp_utc')
        for name, unit in CATS_UNITS.items():
            ds = f.create_dataset(name, data=arrays[name])
            ds.attrs['units'] = unit
            if arrays[name].ndim == 2:
                ds.attrs['axes'] = axes
            ds.dims[0].attach_scale(ts)


def write_cats_netcdf3(path, arrays: dict) -> None:
    from scipy.io import netcdf_file
    with netcdf_file(path, 'w') as f:
        f.createDimension('timestamp_utc', len(arrays['timestamp_utc']))
        f.createDimension('axis', 3)
        v = f.createVariable('timestamp_utc', 'i4', ('timestamp_utc',))
        v[:] = arrays['timestamp_utc']
        v.units = f'seconds since {CATS_EPOCH}'
        for name, unit in CATS_UNITS.items():
            dims = ('timestamp_utc', 'axis') if arrays[name].ndim == 2 else ('timestamp_utc',)
            var = f.createVariable(name, 'f8', dims)
            var[:] = arrays[name]
            var.units = unit
            if arrays[name].ndim == 2:
                var.axes = 'FRU'


def write_cats_csv(path, arrays: dict, nan_rows=(), repeat_rows=()) -> None:
    cols = ['timestamp_utc', 'gx', 'gy', 'gz', 'ax', 'ay', 'az', 'mx', 'my', 'mz', 'temperature']
    data = np.column_stack([arrays['timestamp_utc'], arrays['angular_velocity'], arrays['acceleration'],
                            arrays['magnetic_density'], arrays['temperature']]).astype(object)
    for r in nan_rows:
        data[r, 1] = ''
    rows = []
    for i in range(len(data)):
        rows.append(','.join('' if v == '' else (str(int(v)) if j == 0 else repr(float(v))) for j, v in enumerate(data[i])))
        if i in repeat_rows:
            rows.append(rows[-1])
    with open(path, 'w') as fh:
        fh.write(','.join(cols) + '\n' + '\n'.join(rows) + '\n')


CATS_MAP = {'time': {'column': 'timestamp_utc', 'unit': 's'}, 'rate_hz': 1.0, 'axes': 'FRU',
            'streams': {'gyro': {'column': 'angular_velocity', 'unit': 'mrad/s'},
                        'accel': {'column': 'acceleration', 'unit': 'm/s^2'},
                        'mag': {'column': 'magnetic_density', 'unit': 'uT'},
                        'temperature': {'column': 'temperature', 'unit': 'degC'}}}
CSV_MAP = {'time': {'column': 'timestamp_utc', 'unit': 's', 'epoch': '2021-09-20T08:52:00Z'}, 'rate_hz': 1.0,
           'axes': 'FRU', 'streams': {'gyro': {'column': ['gx', 'gy', 'gz'], 'unit': 'mrad/s'},
                                      'accel': {'column': ['ax', 'ay', 'az'], 'unit': 'm/s^2'},
                                      'mag': {'column': ['mx', 'my', 'mz'], 'unit': 'uT'},
                                      'temperature': {'column': 'temperature', 'unit': 'degC'}}}
