"""Input hygiene and growable column buffers for the streaming carousel core (pure numpy).

Streams arrive in chunks of any size (one sample from a live node up to hour-long arrays).
`InputGuards` applies the package's one input rule (`input_guard.StreamGuard`) to every stream, so
nothing downstream sees NaN or non-increasing stamps: to whole chunks offline (`clean`), or to each
sample as a node receives it (`admit`; the node's chunks are then taken as they are). `Columns` holds
typed sample blocks (`ColumnBlock` dataclasses) between pipeline stages with cheap appends and
front drops.
"""
from __future__ import annotations

from dataclasses import field, fields

import numpy as np

from ..input_guard import CONFIRM_SAMPLES, MAX_JUMP_S, StreamGuard
from ..samples import SensorChunk, slice_samples

# stream -> the value fields that must be finite (an encoder may omit its velocity: NaN is allowed)
CHECKED_FIELDS = {'imu': ('gyro', 'accel'), 'joint': ('position',), 'imu_aux': ('gyro', 'accel'),
                  'temperature': ('temp_c',), 'mag': ('field',)}


# stream -> its checked values in a node's row (nodes/conversions.py layouts)
_ROW_VALUES = {'imu': lambda r: (r[:3], r[3:6]), 'imu_aux': lambda r: (r[:3], r[3:6]), 'joint': lambda r: (r[0],),
               'temperature': lambda r: (r[0],), 'mag': lambda r: (r[:3],)}


class InputGuards:
    """One `StreamGuard` per input stream, with its counters `<stream>_dropped_nonfinite` and
    `<stream>_dropped_order` for the streams in use (the magnetometer only when an angle reference
    uses it, the encoder only for the 'auto' angle source, the auxiliary IMU only with flips)."""

    def __init__(self, use_mag: bool = False, use_joint: bool = True, use_aux: bool = True):
        # a stamp far ahead counts only once samples continue it (a new clock, read as a gap); the
        # revolution stages cannot go back in time, so a clock that jumps back is not followed
        self.guards = {name: StreamGuard(name, max_jump_s=MAX_JUMP_S, confirm_samples=CONFIRM_SAMPLES, allow_back=False)
                       for name in CHECKED_FIELDS}
        self.in_use = {'imu': True, 'joint': use_joint, 'imu_aux': use_aux, 'temperature': True, 'mag': use_mag}

    def admit(self, stream: str, t: float, row) -> bool:
        """One sample of a node's `stream` (its row layout): True if it is kept."""
        return self.guards[stream].keep_one(t, *_ROW_VALUES[stream](row))

    def clean(self, chunk: SensorChunk, admitted: bool = False) -> SensorChunk:
        """The kept samples of the streams in use (an unused stream is neither read nor counted);
        `admitted`: every sample already passed `admit`."""
        kept = {}
        for name, checked in CHECKED_FIELDS.items():
            samples = getattr(chunk, name)
            if self.in_use[name] and samples is not None and len(samples.t):
                if admitted:
                    kept[name] = samples
                else:
                    values = [getattr(samples, f) for f in checked]
                    kept[name] = slice_samples(samples, self.guards[name].keep(samples.t, *values))
        return SensorChunk(**kept)

    def counters(self) -> dict[str, int]:
        return {k: v for name, guard in self.guards.items() if self.in_use[name] for k, v in guard.counters().items()}


def column(*tail: int, dtype=float):
    """A `ColumnBlock` field: one numpy column of shape (N,) + tail."""
    return field(metadata={'tail': tail, 'dtype': dtype})


class ColumnBlock:
    """Base of dataclasses whose fields (declared with `column`) are equally long sample columns."""

    def __len__(self) -> int:
        return len(getattr(self, fields(self)[0].name))

    def rows(self, index):
        """The same kind of block holding only the selected rows."""
        return type(self)(**{f.name: getattr(self, f.name)[index] for f in fields(self)})


class Columns:
    """Append-only table of one `ColumnBlock` type with a movable head (cheap front drops)."""

    def __init__(self, block_type: type):
        self._type = block_type
        self._spec = {f.name: (f.metadata['tail'], f.metadata['dtype']) for f in fields(block_type)}
        self._cap = 256
        self._data = {k: np.empty((self._cap,) + tail, dtype=dt) for k, (tail, dt) in self._spec.items()}
        self._head = 0
        self._size = 0

    def __len__(self) -> int:
        return self._size - self._head

    @property
    def t(self) -> np.ndarray:
        """The stamps column (every block type has one), a view."""
        return self._data['t'][self._head:self._size]

    def view(self):
        """All rows as a block of views (valid until the next append)."""
        return self._type(**{k: self._data[k][self._head:self._size] for k in self._spec})

    def append(self, block) -> None:
        n = len(block)
        if n == 0:
            return
        if self._size + n > self._cap:
            live = len(self)
            if self._head and live + n <= self._cap // 2:
                new_cap = self._cap  # compacting is enough
            else:
                new_cap = max(2 * self._cap, live + n + 256)
            for k, (tail, dt) in self._spec.items():
                fresh = np.empty((new_cap,) + tail, dtype=dt)
                fresh[:live] = self._data[k][self._head:self._size]
                self._data[k] = fresh
            self._cap, self._head, self._size = new_cap, 0, live
        for k in self._spec:
            self._data[k][self._size:self._size + n] = getattr(block, k)
        self._size += n

    def drop_front(self, n: int) -> None:
        self._head = min(self._head + max(int(n), 0), self._size)

    def drop_before(self, t_s: float) -> None:
        """Drop the rows before the last one stamped at or before t_s (that one stays for interpolation)."""
        self.drop_front(int(np.searchsorted(self.t, t_s, side='right')) - 1)

    def clear(self) -> None:
        self._head = self._size = 0

    def take_front(self, n: int):
        """Copy of the first n rows as a block, removed from the table."""
        out = self._type(**{k: self._data[k][self._head:self._size][:n].copy() for k in self._spec})
        self.drop_front(n)
        return out
