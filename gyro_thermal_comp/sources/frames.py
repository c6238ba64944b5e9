"""Declared axis conventions -> the package's sensor frame (REP 103: x forward, y left, z up), and
the checks that the result is a right-handed frame with z up.

A convention names where the logger's x, y, z axes point, one letter each: F/B (forward, back),
L/R (left, right), U/D (up, down); the world-style names read with the vehicle facing north:
N = F, S = B, E = R, W = L (NED = FRD, ENU = RFU, NWU = FLU). `axes_matrix` gives E, whose columns
are the logger's axes in FLU, so a vector's FLU components are E v.

A mirrored (left-handed) convention such as FRU has det E = -1: its y axis is flipped by the
conversion. Specific force and magnetic field are polar vectors and map as E v. Angular velocity is
an axial vector: a logger whose gyro obeys `df/dt = -w x f` inside its own mirrored frame maps as
det(E) E w (`gyro_transform: pseudovector`, the default); one whose gyro axes each follow the right-hand
rule about their own axis maps as E w (`vector`). `KinematicCheck` tells the two apart on any
record that rotates: in the output frame the accelerometer and magnetometer must turn as
df/dt = -w x f. Every further rotation (mounting, levelling a static period) must be proper
(det +1, orthonormal): `check_rotation`.
"""
from __future__ import annotations

import math

import numpy as np

from .base import SourceError

_LETTERS = {'F': (1, 0, 0), 'B': (-1, 0, 0), 'L': (0, 1, 0), 'R': (0, -1, 0), 'U': (0, 0, 1), 'D': (0, 0, -1),
            'N': (1, 0, 0), 'S': (-1, 0, 0), 'W': (0, 1, 0), 'E': (0, -1, 0)}
GYRO_TRANSFORMS = ('pseudovector', 'vector')
UP_TOLERANCE_DEG = 45.0   # mapped z within this of the measured up at rest


def axes_matrix(convention: str) -> np.ndarray:
    """E (3x3): column j is where the logger's axis j points, in FLU. SourceError unless the three
    letters name three different axes."""
    text = str(convention).strip().upper()
    if len(text) != 3 or any(c not in _LETTERS for c in text):
        raise SourceError(f'axes {convention!r}: expected three letters of F/B, L/R, U/D (or N/S, E/W), '
                          'one per logger axis x, y, z, e.g. FLU, FRD, NED, FRU')
    E = np.array([_LETTERS[c] for c in text], dtype=float).T
    if abs(abs(np.linalg.det(E)) - 1.0) > 1e-9:
        raise SourceError(f'axes {convention!r}: two logger axes point along the same line')
    return E


def is_left_handed(E: np.ndarray) -> bool:
    return bool(np.linalg.det(E) < 0)


def gyro_matrix(E: np.ndarray, transform: str = 'pseudovector') -> np.ndarray:
    """The matrix the gyro maps with (module docstring)."""
    if transform not in GYRO_TRANSFORMS:
        raise SourceError(f'gyro_transform {transform!r}: use one of {", ".join(GYRO_TRANSFORMS)}')
    return E * (np.sign(np.linalg.det(E)) if transform == 'pseudovector' else 1.0)


def check_rotation(R, what: str = 'rotation') -> np.ndarray:
    """R as a proper rotation matrix (orthonormal to 1e-6, det +1), else SourceError."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise SourceError(f'{what} must be a finite 3x3 matrix')
    if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-6:
        raise SourceError(f'{what} is not orthonormal (R R^T differs from I by {np.max(np.abs(R @ R.T - np.eye(3))):.2g})')
    det = float(np.linalg.det(R))
    if det < 0:
        raise SourceError(f'{what} is a reflection (det {det:+.3f}), not a rotation: declare mirrored axes '
                          'with `axes` instead')
    return R


def levelling_rotation(up) -> np.ndarray:
    """The smallest proper rotation taking the unit vector `up` (measured, sensor frame) to +z."""
    u = np.asarray(up, dtype=float)
    u = u / np.linalg.norm(u)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(u, z)
    s, c = np.linalg.norm(axis), float(u @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])   # upside down: half a turn about x
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return check_rotation(np.eye(3) + s * K + (1 - c) * (K @ K), 'levelling rotation')


def up_angle_deg(mean_specific_force) -> float:
    """Angle between +z and the mean specific force at rest (which points up), deg."""
    f = np.asarray(mean_specific_force, dtype=float)
    return math.degrees(math.acos(float(np.clip(f[2] / np.linalg.norm(f), -1.0, 1.0))))


class KinematicCheck:
    """Does the gyro turn the way the accelerometer and magnetometer turn? Accumulates, over
    stretches where the unit rotates, the correlation between the measured change of a field
    vector and the change the gyro predicts, df/dt = -w x f (sensor frame, field fixed in the world).
    Fed bin means (0.05 s or one sample, whichever is longer) chunk by chunk."""

    MIN_RATE_RAD_S = 0.1     # rotating: well above any MEMS bias (2 deg/s = 0.035 rad/s)
    MIN_SAMPLES = 30
    Z_REJECT = 4.0           # correlation this many sigmas below zero: mirrored gyro
    # The slope of measured on predicted change is the gyro's scale against the other sensors' turning:
    # a deg/s vs rad/s mix-up gives 57 or 1/57. Judged only where a sample step resolves the turns
    # (point samples of a fast turn alias: the CATS tag's 1 Hz handling gives a slope of 0.05-0.1).
    SCALE_RANGE = (0.5, 2.0)
    SCALE_MAX_STEP_S = 0.1

    def __init__(self):
        self.sxy = self.sxx = self.syy = 0.0
        self.n = 0
        self.n_fine = 0          # rotating samples whose step is at most SCALE_MAX_STEP_S

    def add(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """`t` (n,) s, `w` (n, 3) rad/s, `f` (n, 3) any field fixed in the world, same stamps."""
        if len(t) < 3:
            return
        dt = t[2:] - t[:-2]
        ok = (dt > 0) & (np.linalg.norm(w[1:-1], axis=1) > self.MIN_RATE_RAD_S)
        ok &= np.isfinite(f[2:]).all(axis=1) & np.isfinite(f[:-2]).all(axis=1) & np.isfinite(w[1:-1]).all(axis=1)
        if not ok.any():
            return
        measured = ((f[2:] - f[:-2]) / dt[:, None])[ok]
        predicted = -np.cross(w[1:-1][ok], f[1:-1][ok])
        self.sxy += float(np.sum(measured * predicted))
        self.sxx += float(np.sum(predicted * predicted))
        self.syy += float(np.sum(measured * measured))
        self.n += int(ok.sum())
        self.n_fine += int(np.sum(dt[ok] <= 2 * self.SCALE_MAX_STEP_S))

    def merge(self, other: 'KinematicCheck') -> None:
        self.sxy += other.sxy
        self.sxx += other.sxx
        self.syy += other.syy
        self.n += other.n
        self.n_fine += other.n_fine

    @property
    def slope(self) -> float:
        return self.sxy / self.sxx if self.sxx > 0 else float('nan')

    @property
    def correlation(self) -> float:
        return self.sxy / math.sqrt(self.sxx * self.syy) if self.sxx > 0 and self.syy > 0 else float('nan')

    def verdict(self) -> tuple[str, str]:
        """('ok' | 'mirrored' | 'scale' | 'untested', one-line text)."""
        if self.n < self.MIN_SAMPLES:
            return 'untested', f'gyro handedness not checked: {self.n} rotating samples (needs {self.MIN_SAMPLES})'
        r = self.correlation
        z = r * math.sqrt(self.n)
        text = f'field change vs -w x f over {self.n} rotating samples: correlation {r:+.2f}'
        if z < -self.Z_REJECT:
            return 'mirrored', text
        if self.n_fine >= self.MIN_SAMPLES and self.n_fine >= 0.9 * self.n:
            text += f', gyro scale {self.slope:.3g}'
            lo, hi = self.SCALE_RANGE
            if z > self.Z_REJECT and not lo <= self.slope <= hi:
                return 'scale', text
        return 'ok', text


def rotate_rows(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R applied to each row of v (n, 3)."""
    return np.asarray(v, dtype=float) @ R.T
