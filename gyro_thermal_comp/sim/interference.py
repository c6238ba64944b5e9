"""Magnetic interference episodes: world-fixed fields added to the geomagnetic field for a while.

Two kinds, because a detector that watches only the field norm sees just one of them:
- 'strength': a field of `size` uT in a fixed direction (steel nearby): norm and dip change.
- 'rotate':   the horizontal field turned by `size` deg about the vertical (a local anomaly that bends
  the field): norm and dip stay (almost: a 1 % wobble), heading moves.
The field is exactly zero outside [start_s, end_s); it fades in and out over raised-cosine tapers and
breathes slowly (+-20 %) inside, so it looks neither like a step nor like a constant.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ('strength', 'rotate')


@dataclass(frozen=True)
class Episode:
    kind: str                 # 'strength' (size in uT) or 'rotate' (size in deg)
    start_s: float
    duration_s: float
    size: float
    direction_enu: tuple      # unit vector of the 'strength' field and of the 'rotate' wobble
    period_s: float           # of the slow breathing
    phase_rad: float

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def to_dict(self) -> dict:
        return {'kind': self.kind, 'start_s': self.start_s, 'end_s': self.end_s,
                'size': self.size, 'size_unit': 'uT' if self.kind == 'strength' else 'deg',
                'direction_enu': list(self.direction_enu), 'period_s': self.period_s,
                'phase_rad': self.phase_rad}


def draw_episodes(rng, specs, duration_s: float) -> tuple[Episode, ...]:
    """specs: (kind, start_s, duration_s, size). Episodes are clipped to the run; ones starting after
    its end are dropped. Directions and breathing are drawn from rng (the same for every duration)."""
    episodes = []
    for kind, start, dur, size in specs:
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        period, phase = rng.uniform(60.0, 150.0), rng.uniform(0.0, 2 * np.pi)
        if start < duration_s:
            episodes.append(Episode(kind, float(start), float(min(dur, duration_s - start)), float(size),
                                    tuple(direction.tolist()), float(period), float(phase)))
    return tuple(episodes)


def _envelope(ep: Episode, t: np.ndarray) -> np.ndarray:
    taper = min(20.0, ep.duration_s / 4)
    u = t - ep.start_s
    rise = np.clip(u / taper, 0.0, 1.0)
    fall = np.clip((ep.duration_s - u) / taper, 0.0, 1.0)
    env = np.sin(0.5 * np.pi * np.minimum(rise, fall)) ** 2
    breathe = 0.8 + 0.2 * np.sin(2 * np.pi * u / ep.period_s + ep.phase_rad)
    return np.where((t >= ep.start_s) & (t < ep.end_s), env * breathe, 0.0)


def interference_enu(episodes, t_s, field_enu: np.ndarray) -> np.ndarray:
    """Sum of the episodes' fields at times t_s, (N, 3) T in ENU."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros((len(t), 3))
    horizontal = np.array([field_enu[0], field_enu[1], 0.0])
    for ep in episodes:
        env = _envelope(ep, t)
        if not np.any(env):
            continue
        d = np.asarray(ep.direction_enu)
        if ep.kind == 'strength':
            out += (env * ep.size * 1e-6)[:, None] * d
        else:
            beta = np.deg2rad(ep.size) * env
            c, s = np.cos(beta) - 1.0, np.sin(beta)
            out[:, 0] += c * horizontal[0] - s * horizontal[1]
            out[:, 1] += s * horizontal[0] + c * horizontal[1]
            out += (0.01 * np.linalg.norm(field_enu) * env)[:, None] * d
    return out
