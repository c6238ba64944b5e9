"""Stamps (integer ns since 1970) as float seconds without losing precision: seconds since a time origin.

A float64 second count near 1.7e9 s (any real stamp) has a 2.4e-7 s ulp: 1 kHz sample intervals
would carry 1e-4 relative error, and the STKF's gate decisions (hence heading and parameters) would
depend on the epoch. So every float time in the package is seconds since a *time origin*: an integer
ns, the first stamp of the run (a bag's first message, a node's first sample), subtracted in integer
arithmetic before the conversion to float. A record shifted to any epoch then gives the same floats,
hence bit-identical results.
"""
from __future__ import annotations

import numpy as np

NS_PER_S = 1_000_000_000


def seconds_since(stamp_ns: int, origin_ns: int) -> float:
    """Integer ns since 1970 -> float seconds since `origin_ns` (whole seconds plus the fraction, as a
    ROS stamp's sec + nanosec * 1e-9: a record from origin 0 reads as it always did)."""
    sec, nanosec = divmod(int(stamp_ns) - int(origin_ns), NS_PER_S)
    return sec + nanosec * 1e-9


def ns_at(t_s, origin_ns: int):
    """Float seconds since `origin_ns` -> integer ns since 1970, rounded (k/rate stamps round-trip).
    Scalar in, int out; array in, int64 array out."""
    if np.ndim(t_s) == 0:
        return int(origin_ns) + int(round(float(t_s) * 1e9))
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64) + np.int64(origin_ns)


class TimeOrigin:
    """A run's time origin for code fed stamp by stamp (a node): the first stamp seen, unless given
    (replay gives the bag reader's, so a node computes on the floats an offline run gets)."""

    def __init__(self, ns: int | None = None):
        self.ns = ns

    def seconds(self, stamp_ns: int) -> float:
        if self.ns is None:
            self.ns = int(stamp_ns)
        return seconds_since(stamp_ns, self.ns)

    def stamp_ns(self, t_s: float) -> int:
        return ns_at(t_s, self.ns or 0)
