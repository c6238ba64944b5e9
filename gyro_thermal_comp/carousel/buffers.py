"""Input hygiene and growable column buffers for the streaming carousel core (pure numpy).

Streams arrive in chunks of any size (one sample from a live node up to hour-long arrays).
`InputGuards` applies the package's one input rule (`input_guard.StreamGuard`) to every stream, so
nothing downstream sees NaN or non-increasing stamps. `Columns` holds typed sample blocks
(`ColumnBlock` dataclasses) between pipeline stages with cheap appends and front drops.
"""
from __future__ import annotations

from dataclasses import field, fields

import numpy as np

from ..input_guard import StreamGuard
from ..samples import SensorChunk, slice_samples

# stream -> the value fields that must be finite (an encoder may omit its velocity: NaN is allowed)
CHECKED_FIELDS = {'imu': ('gyro', 'accel'), 'joint': ('position',), 'imu_aux': ('gyro', 'accel'),
                  'temperature': ('temp_c',), 'mag': ('field',)}


class InputGuards:
    """One `StreamGuard` per input stream, with its counters `<stream>_dropped_nonfinite` and
    `<stream>_dropped_order`."""

    def __init__(self, use_mag: bool = False):
        # the magnetometer only when an angle reference uses it (its counters appear only then)
        self.guards = {name: StreamGuard(name) for name in CHECKED_FIELDS if name != 'mag' or use_mag}

    def clean(self, chunk: SensorChunk, use_joint: bool, use_aux: bool) -> SensorChunk:
        """The kept samples of the streams in use (an unused stream is neither read nor counted)."""
        in_use = {'imu': True, 'joint': use_joint, 'imu_aux': use_aux, 'temperature': True, 'mag': 'mag' in self.guards}
        kept = {}
        for name, checked in CHECKED_FIELDS.items():
            samples = getattr(chunk, name)
            if in_use[name] and samples is not None and len(samples.t):
                values = [getattr(samples, f) for f in checked]
                kept[name] = slice_samples(samples, self.guards[name].keep(samples.t, *values))
        return SensorChunk(**kept)

    def counters(self) -> dict[str, int]:
        return {k: v for guard in self.guards.values() for k, v in guard.counters().items()}


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
