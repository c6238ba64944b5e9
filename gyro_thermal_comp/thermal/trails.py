"""Values over a trailing time window, for the magnetic gate's tests: `Trail` keeps the window and
`push_trail` returns the value at its start (a second difference needs it); `LineTrail` also keeps
the sums of its least-squares straight line."""
from __future__ import annotations

import math
from collections import deque


def sqrt_or_nan(v: float) -> float:
    """np.sqrt for one Python float (the same correctly rounded value, NaN below 0), ~20x cheaper."""
    return math.sqrt(v) if v >= 0.0 else math.nan


def push_trail(trail: 'Trail', t: float, v: float) -> float:
    """Append (t, v) to a trail, drop what fell out of its window, return its oldest value. A function,
    not a method: the gate's tests call it several times per observation."""
    q = trail.q
    q.append((t, v))
    cut = t - trail.window_s
    while len(q) > 1 and q[1][0] <= cut:
        q.popleft()
    return q[0][1]


class Trail:
    """Values over a trailing time window (`push_trail` adds one and returns the value at its start)."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self.q: deque = deque()

    def span(self) -> float:
        return self.q[-1][0] - self.q[0][0] if self.q else 0.0


class LineTrail(Trail):
    """A trail that keeps the sums of its least-squares straight line (`line`: O(1) per observation,
    for a window of a thousand). Sums about the first entry since the last rebuild, rebuilt once that
    is 10 windows old, so they keep their precision through a shut of hours."""

    def __init__(self, window_s: float):
        super().__init__(window_s)
        self.rebuild()

    def rebuild(self) -> None:
        """Sums afresh from the entries (after a clear, or the values were re-expressed)."""
        q = self.q
        self._base = q[0] if q else None
        self._sums = [0.0] * 6     # n, u, u^2, v, u v, v^2 with u, v = t, r about the base
        for t, v in q:
            self._add(t, v, 1.0)

    def clear(self) -> None:
        self.q.clear()
        self.rebuild()

    def _add(self, t: float, v: float, w: float) -> None:
        u, v = t - self._base[0], v - self._base[1]
        a = self._sums
        a[0] += w
        a[1] += w * u
        a[2] += w * u * u
        a[3] += w * v
        a[4] += w * u * v
        a[5] += w * v * v

    def push(self, t: float, v: float) -> None:
        q = self.q
        if not q:
            self._base = (t, v)
        q.append((t, v))
        self._add(t, v, 1.0)
        cut = t - self.window_s
        while len(q) > 1 and q[1][0] <= cut:
            self._add(*q.popleft(), -1.0)
        if t - self._base[0] > 10.0 * self.window_s:
            self.rebuild()

    def line(self) -> tuple[float, float]:
        """Least-squares straight line through the trail: (slope per s, rms of the residuals)."""
        n, su, suu, sv, suv, svv = self._sums
        var_u = suu - su * su / n
        cov = suv - su * sv / n
        slope = cov / var_u if var_u > 0 else 0.0
        rss = svv - sv * sv / n - slope * cov
        return slope, sqrt_or_nan(max(rss, 0.0) / n)
