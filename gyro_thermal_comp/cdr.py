"""Vectorised CDR for the fixed-layout messages: numpy arrays <-> per-message bytes, no per-message objects.

Wire format (what rosbags' `serialize_cdr` and rclpy's `serialize_message` write, XCDR1 little endian):
a 4-byte encapsulation header `00 01 00 00`, then the fields in definition order, each primitive
aligned to its own size *relative to the byte after the encapsulation header* (the body), with zero
padding. For a message made of a `std_msgs/Header` followed only by float64 fields (plain, fixed
arrays or structs of them: Imu, MagneticField, Temperature, PoseWithCovarianceStamped), the body is

    0  int32  stamp.sec          4  uint32 stamp.nanosec
    8  uint32 len(frame_id) + 1  12 frame_id bytes (UTF-8), NUL
    align8(13 + L)               the float64 fields, back to back (8-aligned from here on)

so one frame_id length L gives one fixed record size, and n messages are one numpy structured array
of that dtype: encoding fills it and slices its bytes; decoding views the joined bytes as it. The
field list is derived from rosbags' message definitions (`TYPESTORE.fielddefs`), not typed here.

Decoding never changes behaviour: a message the fast path does not recognise exactly (big-endian or
other encapsulation, a length that does not match its frame_id, trailing bytes, a missing string
terminator, invalid UTF-8) is handed to rosbags' deserializer, and what rosbags cannot read either
is reported in `Decoded.errors` for the caller to drop and count.

`OneMessage` is the same layout for one message at a time (a live node's raw subscriptions and
publishers), through `struct`: numpy's per-call cost would dominate a single message. It takes what
`decode` takes and hands the rest to `decode`, so both read every message alike.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import struct
from functools import lru_cache
from typing import Sequence

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
NS_PER_S = 1_000_000_000
ENCAPSULATION = bytes([0, 1, 0, 0])   # CDR little endian, options 0
_HEADER = 'std_msgs/msg/Header'
_INT32 = (-(1 << 31), (1 << 31) - 1)

IMU = 'sensor_msgs/msg/Imu'
MAG = 'sensor_msgs/msg/MagneticField'
TEMPERATURE = 'sensor_msgs/msg/Temperature'
POSE_COV_STAMPED = 'geometry_msgs/msg/PoseWithCovarianceStamped'


@dataclass(frozen=True)
class _Leaf:
    name: str          # dotted path below the message, e.g. 'pose.covariance'
    path: tuple        # attribute names from the message to the value
    members: tuple     # struct of float64: its member names (x, y, z[, w]); else ()
    count: int         # float64 values; 0 = a plain float64 scalar

    @property
    def width(self) -> int:
        return max(self.count, 1)

    def value_of(self, msg) -> list[float]:
        """The leaf's numbers from a rosbags message object (the fallback path)."""
        obj = msg
        for name in self.path:
            obj = getattr(obj, name)
        if self.members:
            return [getattr(obj, m) for m in self.members]
        return [obj] if self.count == 0 else list(obj)


def _leaves(msgtype: str, fields, prefix: tuple) -> list[_Leaf]:
    """Flatten fields into float64 leaves: a scalar, a fixed array, or a struct of plain float64s
    (Vector3, Quaternion, Point) each become one leaf; other structs are walked into."""
    out = []
    for name, (kind, spec) in fields:
        path = (*prefix, name)
        leaf_name = '.'.join(path)
        if kind == Nodetype.BASE and spec[0] == 'float64':
            out.append(_Leaf(leaf_name, path, (), 0))
        elif kind == Nodetype.ARRAY and spec[0] == (Nodetype.BASE, ('float64', 0)):
            out.append(_Leaf(leaf_name, path, (), spec[1]))
        elif kind == Nodetype.NAME:
            sub = TYPESTORE.fielddefs[spec][1]
            if all(k == Nodetype.BASE and s[0] == 'float64' for _, (k, s) in sub):
                out.append(_Leaf(leaf_name, path, tuple(n for n, _ in sub), len(sub)))
            else:
                out += _leaves(spec, sub, path)
        else:
            raise ValueError(f'{msgtype}.{name} is not float64: no fixed CDR layout')
    return out


@lru_cache(maxsize=None)
def layout(msgtype: str) -> tuple[_Leaf, ...]:
    """The float64 fields after the header, in wire order; ValueError if `msgtype` is not a Header
    followed by float64 fields only."""
    fields = TYPESTORE.fielddefs[msgtype][1]
    if not fields or fields[0] != ('header', (Nodetype.NAME, _HEADER)):
        raise ValueError(f'{msgtype} does not start with a std_msgs/Header')
    return tuple(_leaves(msgtype, fields[1:], ()))


def floats_at(frame_len: int) -> int:
    """Byte offset of the float64 block in a message whose frame_id is `frame_len` UTF-8 bytes:
    4 + align8(13 + L), the rule in the module docstring."""
    return 4 + (-(-(13 + frame_len) // 8) * 8)


@lru_cache(maxsize=256)
def record_dtype(msgtype: str, frame_len: int) -> np.dtype:
    """The structured dtype of one whole message (encapsulation header included) whose frame_id
    is `frame_len` UTF-8 bytes. The float64 block starts at body offset align8(13 + frame_len)."""
    leaves = layout(msgtype)
    names = ['encapsulation', 'sec', 'nanosec', 'frame_len', 'frame']
    formats = [('u1', 4), '<i4', '<u4', '<u4', ('u1', frame_len + 1)]
    offsets = [0, 4, 8, 12, 16]
    pos = floats_at(frame_len)
    for leaf in leaves:
        names.append(leaf.name)
        formats.append('<f8' if leaf.count == 0 else ('<f8', leaf.count))
        offsets.append(pos)
        pos += 8 * leaf.width
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': pos})


# ---------------------------------------------------------------- encode
def encode(msgtype: str, stamps_ns, frame_id: str, values: dict) -> list[bytes]:
    """n messages of `msgtype` -> n CDR byte strings, byte-for-byte rosbags' serialize_cdr.

    `stamps_ns`: (n,) integer ns since 1970 (header.stamp; seconds must fit int32); `frame_id` one
    string for all; `values`: leaf name (see `layout`) -> array broadcastable to (n,) or (n, k);
    a leaf not given is zero. ValueError for an unknown leaf, a stamp out of range or a bad shape."""
    stamps = np.asarray(stamps_ns)
    if stamps.ndim != 1 or not (stamps.dtype.kind in 'iu' or stamps.size == 0):
        raise ValueError(f'stamps_ns must be a 1-D integer array (ns since 1970), not {stamps.dtype} {stamps.shape}')
    stamps = stamps.astype(np.int64)
    n = len(stamps)
    leaves = {leaf.name: leaf for leaf in layout(msgtype)}
    unknown = set(values) - set(leaves)
    if unknown:
        raise ValueError(f'{msgtype} has no float64 field(s) {sorted(unknown)}; known: {sorted(leaves)}')
    frame = frame_id.encode()
    rec = np.zeros(n, dtype=record_dtype(msgtype, len(frame)))
    sec, nanosec = np.divmod(stamps, NS_PER_S)   # floor: a negative stamp keeps 0 <= nanosec < 1e9
    if n and (sec.min() < _INT32[0] or sec.max() > _INT32[1]):
        raise ValueError('header stamp seconds out of int32 range')
    rec['encapsulation'] = np.frombuffer(ENCAPSULATION, np.uint8)
    rec['sec'], rec['nanosec'] = sec, nanosec
    rec['frame_len'] = len(frame) + 1
    rec['frame'] = np.frombuffer(frame + b'\0', np.uint8)
    for name, value in values.items():
        shape = (n,) if leaves[name].count == 0 else (n, leaves[name].count)
        try:
            rec[name] = np.broadcast_to(np.asarray(value, dtype=np.float64), shape)
        except ValueError:
            raise ValueError(f'{msgtype}.{name}: shape {np.shape(value)} does not broadcast to {shape}') from None
    buf, size = rec.tobytes(), rec.dtype.itemsize
    return [buf[i:i + size] for i in range(0, len(buf), size)]


def encode_imu(stamps_ns, frame_id: str, orientation=(0.0, 0.0, 0.0, 1.0), orientation_covariance=0.0,
               angular_velocity=0.0, angular_velocity_covariance=0.0, linear_acceleration=0.0,
               linear_acceleration_covariance=0.0) -> list[bytes]:
    """sensor_msgs/Imu: orientation x, y, z, w (n, 4); angular_velocity rad/s and
    linear_acceleration m/s^2 (n, 3); covariances row-major (n, 9); each broadcastable (one (9,)
    row for all). Defaults are the message's (identity quaternion, zeros)."""
    return encode(IMU, stamps_ns, frame_id, {
        'orientation': orientation, 'orientation_covariance': orientation_covariance,
        'angular_velocity': angular_velocity, 'angular_velocity_covariance': angular_velocity_covariance,
        'linear_acceleration': linear_acceleration, 'linear_acceleration_covariance': linear_acceleration_covariance})


def encode_pose_with_covariance_stamped(stamps_ns, frame_id: str, orientation, position=0.0,
                                        covariance=0.0) -> list[bytes]:
    """geometry_msgs/PoseWithCovarianceStamped: position m (n, 3), orientation x, y, z, w (n, 4),
    covariance row-major 6x6 (n, 36) over x, y, z, roll, pitch, yaw; each broadcastable."""
    return encode(POSE_COV_STAMPED, stamps_ns, frame_id, {
        'pose.pose.position': position, 'pose.pose.orientation': orientation, 'pose.covariance': covariance})


def encode_mag(stamps_ns, frame_id: str, magnetic_field, magnetic_field_covariance=0.0) -> list[bytes]:
    """sensor_msgs/MagneticField: field T (n, 3), covariance T^2 (n, 9), broadcastable."""
    return encode(MAG, stamps_ns, frame_id, {'magnetic_field': magnetic_field,
                                             'magnetic_field_covariance': magnetic_field_covariance})


def encode_temperature(stamps_ns, frame_id: str, temperature, variance=0.0) -> list[bytes]:
    """sensor_msgs/Temperature: temperature degC (n,), variance degC^2 (n,), broadcastable."""
    return encode(TEMPERATURE, stamps_ns, frame_id, {'temperature': temperature, 'variance': variance})


# ---------------------------------------------------------------- decode
@dataclass
class Decoded:
    """The messages that could be decoded, in input order, as arrays."""
    index: np.ndarray                 # (m,) int64: position of each decoded message in the input list
    stamp_ns: np.ndarray              # (m,) int64: header.stamp, ns since 1970
    frame_id: np.ndarray              # (m,) object: header.frame_id (str)
    fields: dict[str, np.ndarray]     # leaf name -> (m,) or (m, k) float64 (see `layout`)
    errors: list[tuple[int, Exception]] = field(default_factory=list)   # (input position, why) of the rest
    fallback: int = 0                 # how many of the decoded went through rosbags' deserializer

    def __len__(self) -> int:
        return len(self.index)


def decode(raws: Sequence[bytes], msgtype: str) -> Decoded:
    """n CDR messages of `msgtype` (a Header plus float64 fields) -> arrays; what rosbags'
    deserializer would return, field for field, bit for bit. Messages neither path can read are
    listed in `errors` (rosbags' exception) and left out."""
    leaves = layout(msgtype)
    n = len(raws)
    stamp = np.zeros(n, np.int64)
    frames = np.empty(n, dtype=object)
    out = {leaf.name: np.zeros((n, leaf.count) if leaf.count else n) for leaf in leaves}
    done = np.zeros(n, bool)
    if n:
        _decode_fast(raws, msgtype, stamp, frames, out, done)
    errors, fallback = [], 0
    for i in np.flatnonzero(~done).tolist():
        try:
            msg = TYPESTORE.deserialize_cdr(raws[i], msgtype)
        except Exception as exc:   # the caller drops it; rosbags says why
            errors.append((i, exc))
            continue
        s = msg.header.stamp
        stamp[i], frames[i] = s.sec * NS_PER_S + s.nanosec, msg.header.frame_id
        for leaf in leaves:
            out[leaf.name][i] = leaf.value_of(msg) if leaf.count else leaf.value_of(msg)[0]
        done[i] = True
        fallback += 1
    keep = np.flatnonzero(done)
    if len(keep) == n:
        return Decoded(keep, stamp, frames, out, errors, fallback)
    return Decoded(keep, stamp[keep], frames[keep], {k: v[keep] for k, v in out.items()}, errors, fallback)


def _decode_fast(raws, msgtype, stamp, frames, out, done) -> None:
    """Fill the rows of messages whose bytes match the fixed layout exactly; mark them in `done`."""
    n = len(raws)
    lengths = np.fromiter(map(len, raws), np.int64, n)
    joined = b''.join(raws)
    buf = np.frombuffer(joined, np.uint8)
    starts = np.zeros(n, np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    body = 8 * sum(leaf.width for leaf in layout(msgtype))
    frame_len = np.full(n, -1, np.int64)      # len(frame_id) in bytes, -1 where unreadable
    big = np.flatnonzero(lengths >= 16)
    if len(big):
        field_ = buf[starts[big, None] + np.arange(12, 16)].view('<u4')[:, 0].astype(np.int64)
        frame_len[big] = field_ - 1           # the length field counts the NUL
    aligned = -(-(13 + frame_len) // 8) * 8
    ok = (frame_len >= 0) & (lengths == 4 + aligned + body)
    head = buf[starts[ok, None] + np.arange(2)]
    ok[np.flatnonzero(ok)[~((head[:, 0] == 0) & (head[:, 1] == 1))]] = False
    if not ok.any():
        return
    uniform = ok.all() and (frame_len == frame_len[0]).all()
    for L in np.unique(frame_len[ok]).tolist():
        dtype = record_dtype(msgtype, L)
        if uniform:   # every message the same size: the joined bytes are the record array
            idx, rec = np.arange(n), np.frombuffer(joined, dtype)
        else:
            idx = np.flatnonzero(ok & (frame_len == L))
            rec = buf[starts[idx, None] + np.arange(dtype.itemsize)].view(dtype)[:, 0]
        good = _frames(rec['frame'], frames, idx)
        idx, rec = idx[good], rec[good]
        stamp[idx] = rec['sec'].astype(np.int64) * NS_PER_S + rec['nanosec']
        for name, arr in out.items():
            arr[idx] = rec[name]
        done[idx] = True


def _frames(raw_frames: np.ndarray, frames: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Decode the frame_id bytes (k, L + 1) of one group into `frames[idx]`; returns the mask of
    rows with a NUL terminator and valid UTF-8 (the others go to rosbags, which rejects them)."""
    good = raw_frames[:, -1] == 0
    if (raw_frames == raw_frames[0]).all():      # the usual case: one frame_id
        unique, inverse = raw_frames[:1], np.zeros(len(raw_frames), np.int64)
    else:
        unique, inverse = np.unique(raw_frames, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
    for j, row in enumerate(unique):
        try:
            text = row[:-1].tobytes().decode()
        except UnicodeDecodeError:
            good &= inverse != j
            continue
        frames[idx[inverse == j]] = text
    return good


# ---------------------------------------------------------------- one message at a time
_FRAME_LEN = struct.Struct('<I')   # at byte 12: len(frame_id) + 1


class MalformedMessage(ValueError):
    """Bytes that neither the fixed layout nor rosbags' deserializer reads as the message type."""


def header_cdr(stamp_ns: int, frame_id: str) -> bytes:
    """Encapsulation and std_msgs/Header as CDR (the first 17 + len(frame_id) bytes of a message)."""
    frame = frame_id.encode()
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return struct.pack(f'<4siII{len(frame) + 1}s', ENCAPSULATION, sec, nanosec, len(frame) + 1, frame)


def header_fields(header: bytes) -> tuple[int, int, str]:
    """`header_cdr`'s bytes -> (stamp sec, nanosec, frame_id)."""
    sec, nanosec = struct.unpack_from('<iI', header, 4)
    return sec, nanosec, header[16:-1].decode()


class OneMessage:
    """One message of `msgtype` (a Header plus float64 fields) at a time, in `record_dtype`'s layout:
    `decode(raw)` gives (stamp ns, frame_id, header bytes, every float64 in wire order) and
    `encode(header, values)` the bytes of a message; `offset(leaf)` is where a leaf starts in those
    values. Byte for byte what `decode`, `encode` (and rclpy) read and write."""

    def __init__(self, msgtype: str):
        self.msgtype = msgtype
        leaves, start = layout(msgtype), 0
        self._offsets = {}
        for leaf in leaves:
            self._offsets[leaf.name], start = start, start + leaf.width
        self.body = struct.Struct(f'<{start}d')
        self._head: dict[int, struct.Struct] = {}   # frame_id length -> struct of the header fields

    def offset(self, leaf: str) -> int:
        return self._offsets[leaf]

    def _header(self, frame_len: int) -> struct.Struct:
        """Encapsulation kind, sec, nanosec, frame_id + NUL (cached per frame_id length in use)."""
        head = self._head.get(frame_len)
        if head is None:
            head = self._head[frame_len] = struct.Struct(f'<xB2xiI4x{frame_len + 1}s')
        return head

    def decode(self, raw: bytes) -> tuple[int, str, bytes, tuple]:
        """(stamp ns, frame_id, the header's bytes as `header_cdr` writes them, the float64 values);
        MalformedMessage if rosbags cannot read it either."""
        if len(raw) >= 16:
            frame_len = _FRAME_LEN.unpack_from(raw, 12)[0] - 1
            if frame_len >= 0 and len(raw) == floats_at(frame_len) + self.body.size and raw[0] == 0:
                kind, sec, nanosec, frame = self._header(frame_len).unpack_from(raw)
                if kind == 1 and frame[-1] == 0:
                    try:
                        frame_id = frame[:-1].decode()
                    except UnicodeDecodeError:
                        frame_id = None
                    if frame_id is not None:
                        return (sec * NS_PER_S + nanosec, frame_id, ENCAPSULATION + raw[4:17 + frame_len],
                                self.body.unpack_from(raw, floats_at(frame_len)))
        return self._decode_other(raw)

    def _decode_other(self, raw: bytes) -> tuple[int, str, bytes, tuple]:
        """What the fixed layout does not take exactly (big endian, padding, ...): `decode` (rosbags)."""
        try:
            got = decode([bytes(raw)], self.msgtype)
        except Exception as exc:   # whatever the bytes are, the caller drops them: never an error of its own
            raise MalformedMessage(f'not a {self.msgtype}: {exc}') from None
        if not len(got):
            raise MalformedMessage(f'not a {self.msgtype}: {got.errors[0][1]}')
        values = []
        for leaf in layout(self.msgtype):
            values += np.atleast_1d(got.fields[leaf.name][0]).tolist()
        stamp_ns, frame_id = int(got.stamp_ns[0]), str(got.frame_id[0])
        return stamp_ns, frame_id, header_cdr(stamp_ns, frame_id), tuple(values)

    def encode(self, header: bytes, values) -> bytes:
        """A message from its header's bytes (`header_cdr`, or `decode`'s) and every float64 value."""
        return b''.join((header, bytes(floats_at(len(header) - 17) - len(header)), self.body.pack(*values)))
