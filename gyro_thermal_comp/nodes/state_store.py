"""Learned drift parameters on disk: atomic writes, checked reads, one owner (no ROS here).

A vehicle is switched off without warning: the file is never half-written (temporary file in the
same folder, fsync, rename, fsync of the folder). A file that cannot be used means a cold start,
never a crash, and is moved aside (`<name>.rejected-<UTC time>`) rather than overwritten, so a
state worth hours of learning can still be inspected or restored by hand. An advisory lock on
`<name>.lock` keeps two nodes from overwriting each other's learning in one file. `warm_start` is
what a node does with its `state_file` parameter at start.
"""
from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

FORMAT = 'gyro_thermal_comp/stkf_state/1'
_TMP_TAG = 'tmp-'          # temp files: .<name>.tmp-XXXXXXXX (mkstemp adds 8 of [a-z0-9_])
_P_SYMMETRY_REL = 1e-6     # |P - P^T| allowed, relative to max |P| (JSON round trip is exact)


class StateStoreError(RuntimeError):
    """The store cannot do what was asked (not the owner, or refusing to write an invalid state)."""


class StateFileInUse(StateStoreError):
    """Another process (or another StateStore in this one) holds the lock on this state file."""


@dataclass(frozen=True)
class LoadResult:
    state: dict | None             # None: cold start
    status: str                    # 'warm start from …' or 'cold start: <reason>[; moved aside to …]'
    moved_to: Path | None = None   # where a rejected file went

    @property
    def warm(self) -> bool:
        return self.state is not None


class StateStore:
    """One state file owned by one process. `acquire()` before `load()`/`save()`; `release()` (or
    process death) lets the next owner in."""

    def __init__(self, path):
        self.path = Path(path)
        self.lock_path = self.path.with_name(self.path.name + '.lock')
        self._lock_file = None
        self._save_blocked: str | None = None   # a rejected file we could not move aside

    # ------------------------------------------------------------------ ownership
    @property
    def held(self) -> bool:
        return self._lock_file is not None

    def acquire(self) -> None:
        """Take the lock (idempotent) and remove temp files of earlier killed saves.
        Raises StateFileInUse if another owner has it; OSError if the folder is unusable."""
        if self.held:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        f = open(self.lock_path, 'a+')  # never truncated before we own it: it names the owner
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            f.seek(0)
            owner = f.read().strip() or 'unknown'
            f.close()
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                raise StateFileInUse(f'state file {self.path} is in use by another node '
                                     f'(lock {self.lock_path} held by pid {owner})') from None
            raise
        f.truncate(0)
        f.write(f'{os.getpid()}\n')
        f.flush()
        self._lock_file = f
        self._remove_orphans()

    def release(self) -> None:
        """Give the lock up (idempotent). The lock file stays: deleting it would let a process that
        opened it just before lock an unlinked file while a third one creates a new one."""
        if self._lock_file is not None:
            self._lock_file.close()   # closing the last descriptor releases the flock
            self._lock_file = None

    def __enter__(self) -> 'StateStore':
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def _remove_orphans(self) -> None:
        # Only names this module creates (current and earlier prefix); safe because we hold the lock,
        # so no save of ours is under way.
        pattern = re.compile(rf'\.{re.escape(self.path.name)}\.(?:{_TMP_TAG})?[a-z0-9_]{{8}}')
        for p in self.path.parent.iterdir():
            if pattern.fullmatch(p.name) and p.is_file() and not p.is_symlink():
                p.unlink(missing_ok=True)

    # ------------------------------------------------------------------ load
    def load(self, check: Callable[[dict], None] | None = None) -> LoadResult:
        """Read and check the file (acquiring the lock if needed: may raise StateFileInUse).
        `check(state)` raises ValueError with a reason when the state does not fit the running model.
        Any rejection: cold start, the file moved aside."""
        self.acquire()
        if not self.path.exists():
            return LoadResult(None, f'cold start: no state file at {self.path}')
        state, reason = _read(self.path)
        if reason is None and check is not None:
            try:
                check(state)
            except (ValueError, TypeError, KeyError, ArithmeticError) as exc:
                reason = f'does not fit this model ({exc})'
        if reason is None:
            return LoadResult(state, f'warm start from {self.path}')
        reason = f'state file {self.path} {reason}'
        try:
            moved = self._move_aside()
        except OSError as exc:
            self._save_blocked = f'{self.path} was rejected and could not be moved aside'
            return LoadResult(None, f'cold start: {reason}; could not move it aside ({exc}), not saving over it')
        return LoadResult(None, f'cold start: {reason}; moved aside to {moved}', moved)

    def _move_aside(self) -> Path:
        stamp = time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())
        target = self.path.with_name(f'{self.path.name}.rejected-{stamp}')
        n = 1
        while target.exists() or target.is_symlink():   # never overwrite an earlier rejected file
            target = self.path.with_name(f'{self.path.name}.rejected-{stamp}-{n}')
            n += 1
        os.rename(self.path, target)   # we hold the lock: nobody else creates names here meanwhile
        _fsync_dir(self.path.parent)
        return target

    # ------------------------------------------------------------------ save
    def save(self, state: dict) -> None:
        """Atomically write `state` (ThermalDriftEstimator.get_state() with 'x'). Raises
        StateStoreError when not the lock owner or when the state would not load back (the last good
        file stays); OSError on disk errors."""
        if not self.held:
            raise StateStoreError(f'not saving {self.path}: this store does not hold {self.lock_path}')
        if self._save_blocked:
            raise StateStoreError(f'not saving: {self._save_blocked}')
        record = {'format': FORMAT, 'saved_unix_s': time.time(), **state}
        problem = check_record(record)
        if problem:
            raise StateStoreError(f'not saving {self.path}: state {problem}')
        _write_atomic(self.path, record)


@dataclass(frozen=True)
class WarmStart:
    """What a node's start did with its state file."""
    store: StateStore | None   # the owned store to save to; None: no persistence
    status: str                # 'warm start from …' or 'cold start: <reason>'
    rejected: bool = False     # a file that did not fit was moved aside
    level: str | None = None   # how to log `status`: 'info', 'warning', 'error'; None: not at all


def warm_start(path: str, set_state: Callable[[dict], None]) -> WarmStart:
    """Own the state file at `path` and load it through `set_state` (which validates before it changes
    anything); a file that does not fit is moved aside (cold start). A folder that is missing or
    read-only: cold start without persistence. A file in use by another node raises StateFileInUse."""
    if not path:
        return WarmStart(None, 'cold start: no state_file parameter')
    store = StateStore(path)
    try:
        result = store.load(set_state)
    except OSError as exc:
        return WarmStart(None, f'cold start: cannot use state file {path} ({exc}); not saving', level='error')
    return WarmStart(store, result.status, result.moved_to is not None, 'info' if result.warm else 'warning')


def _write_atomic(path: Path, record: dict) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.{_TMP_TAG}', dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as f:
            json.dump(record, f, indent=1, allow_nan=False)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)   # so the rename itself survives a power cut


# ---------------------------------------------------------------------- checks
def _read(path: Path) -> tuple[dict | None, str | None]:
    """(state, None) or (None, reason)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        return None, f'is unreadable ({exc})'
    if not text.strip():
        return None, 'is empty'
    try:
        record = json.loads(text, parse_constant=_no_constant)
    except ValueError as exc:
        return None, f'is not valid JSON ({exc})'
    problem = check_record(record)
    if problem:
        return None, problem
    return {k: v for k, v in record.items() if k not in ('format', 'saved_unix_s')}, None


def _no_constant(name: str):
    raise ValueError(f'non-finite number {name}')


def check_record(record) -> str | None:
    """Why a file record is unusable (types, finiteness, shapes; not magnitudes), or None."""
    if not isinstance(record, dict):
        return 'is not a JSON object'
    if record.get('format') != FORMAT:
        return f'has format {record.get("format")!r}, not {FORMAT!r}'
    x = record.get('x')
    if not isinstance(x, list) or not x:
        return 'has no parameter list x'
    bad = [i for i, v in enumerate(x) if _real(v) is None]
    if bad:
        return f'has a non-finite or non-numeric x[{bad[0]}] = {x[bad[0]]!r}'
    terms = record.get('terms')
    if not isinstance(terms, list) or not all(isinstance(t, str) for t in terms) or len(terms) != len(x):
        return f'has terms {terms!r}: not {len(x)} names for x'
    t_ref = record.get('temperature_ref_c')
    if t_ref is not None and _real(t_ref) is None:
        return f'has temperature_ref_c = {t_ref!r}, not a finite number'
    if record.get('P') is not None:
        problem = _covariance_problem(record['P'], len(x))
        if problem:
            return f'has a malformed covariance P: {problem}'
    return None


def _covariance_problem(P, n: int) -> str | None:
    if not isinstance(P, list) or len(P) != n or not all(isinstance(r, list) and len(r) == n for r in P):
        return f'not {n} x {n}'
    values = [_real(v) for r in P for v in r]
    if any(v is None for v in values):
        return 'a non-finite or non-numeric entry'
    m = np.array(values).reshape(n, n)
    if np.any(np.diag(m) < 0):
        return 'negative variance on the diagonal'
    if np.max(np.abs(m - m.T)) > _P_SYMMETRY_REL * np.max(np.abs(m)):
        return 'not symmetric'
    return None


def _real(v) -> float | None:
    """v as a finite float, or None (JSON true/false are bools, and bool is an int in Python)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        f = float(v)
    except OverflowError:   # a huge JSON integer
        return None
    return f if math.isfinite(f) else None


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
