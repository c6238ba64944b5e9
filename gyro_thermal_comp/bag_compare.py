"""Are two bags the same recording, to floating-point rounding? (regenerated bags, reference outputs)

Regenerating a bag on another CPU gives values that differ in the last bits: numpy picks SIMD
kernels per CPU (`sin`, `exp`, reductions) and OpenBLAS picks its own kernels (`OPENBLAS_CORETYPE`),
so sums and products round differently. What must not differ at all is the structure: topics,
message types, counts, offered QoS and type hashes, the configuration's keys, strings and integers
(its floats to rtol: some are derived from random draws with numpy) and stamps (the time origin and
the stamps since it, i.e. the stamps to the ns). Values are compared per stream and field
as `|ours - theirs| <= atol + rtol * |theirs|`, with `atol = atol_scale * max|ours|` of that field in
the chunk, so a component that is near zero where the rest is large is not held to a relative bound
it cannot meet. Defaults: rtol 1e-9, atol_scale 1e-12 (float64 rounding is ~1e-16, accumulated over
the simulator's integrations it stays below ~1e-13; a real change is far larger).
"""
from __future__ import annotations

import json
import math
from dataclasses import fields

import numpy as np

from . import topics
from .bag_io import BagReader

RTOL = 1e-9
ATOL_SCALE = 1e-12


def bag_differences(ours, theirs, *, rtol: float = RTOL, atol_scale: float = ATOL_SCALE,
                    chunk_s: float = 600.0) -> list[str]:
    """Every way `theirs` differs from `ours` beyond rounding, one line each (empty: the same).

    Streams both bags in lockstep chunks, so bags of any length fit in memory."""
    problems = []
    with BagReader(ours) as a, BagReader(theirs) as b:
        layout_a = [(t.topic, t.msgtype, t.count) for t in a.topics]
        layout_b = [(t.topic, t.msgtype, t.count) for t in b.topics]
        if layout_a != layout_b:
            return [f'{theirs}: topics, types or counts differ: {layout_a} != {layout_b}']
        for ta, tb in zip(a.topics, b.topics):
            if (ta.offered_qos, ta.type_hash) != (tb.offered_qos, tb.type_hash):
                problems.append(f'{theirs}: {ta.topic} offered QoS or type hash differs')
        if a.time_origin_ns != b.time_origin_ns:
            problems.append(f'{theirs}: starts at {b.time_origin_ns} ns since 1970, not {a.time_origin_ns} ns')
        problems += [f'{theirs}: {topics.SIM_CONFIG} {p}'
                     for p in config_differences(a.text(topics.SIM_CONFIG), b.text(topics.SIM_CONFIG), rtol)]
        worst: dict[tuple[str, str], tuple[float, float]] = {}   # (stream, field) -> (excess, |diff|)
        for ca, cb in zip(a.chunks(chunk_s), b.chunks(chunk_s), strict=True):
            sa, sb = ca.streams(), cb.streams()
            if sorted(sa) != sorted(sb):
                problems.append(f'{theirs}: streams {sorted(sb)} where {ours} has {sorted(sa)}')
                continue
            for stream, samples in sa.items():
                other = sb[stream]
                for f in fields(samples):
                    x, y = getattr(samples, f.name), getattr(other, f.name)
                    if x.shape != y.shape:
                        problems.append(f'{theirs}: {stream}.{f.name} shape {y.shape} != {x.shape}')
                        continue
                    if f.name == 't':
                        if not np.array_equal(x, y):
                            problems.append(f'{theirs}: {stream} stamps differ')
                        continue
                    excess, diff = _excess(x, y, rtol, atol_scale)
                    if excess > worst.get((stream, f.name), (0.0, 0.0))[0]:
                        worst[(stream, f.name)] = (excess, diff)
        for (stream, name), (_, diff) in worst.items():
            problems.append(f'{theirs}: {stream}.{name} differs from {ours} by up to {diff:.3g} '
                            f'(beyond rtol {rtol:g} + {atol_scale:g} of the field scale)')
    return problems


def config_differences(ours: list[str], theirs: list[str], rtol: float = RTOL) -> list[str]:
    """Simulator configurations (JSON texts): keys, strings, integers and flags exactly; floats to
    `rtol` (some are drawn, then derived with numpy: a unit's hard-iron vector is a length times a
    direction, whose last bits depend on the CPU's kernels). One line per difference."""
    if len(ours) != len(theirs):
        return [f'has {len(theirs)} messages, not {len(ours)}']
    out: list[str] = []
    for a, b in zip(ours, theirs):
        try:
            _json_diff(json.loads(a), json.loads(b), rtol, '', out)
        except ValueError:
            if a != b:
                out.append('differs (not JSON)')
    return out


def _json_diff(a, b, rtol: float, path: str, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            out.append(f'{path or "/"}: keys {sorted(b)} != {sorted(a)}')
            return
        for k in a:
            _json_diff(a[k], b[k], rtol, f'{path}/{k}', out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            _json_diff(x, y, rtol, f'{path}[{i}]', out)
    elif isinstance(a, float) and isinstance(b, float):
        if not (a == b or abs(a - b) <= rtol * max(abs(a), abs(b)) or (math.isnan(a) and math.isnan(b))):
            out.append(f'{path}: {b!r} != {a!r} (beyond rtol {rtol:g})')
    elif a != b or type(a) is not type(b):
        out.append(f'{path}: {b!r} != {a!r}')


def _excess(x: np.ndarray, y: np.ndarray, rtol: float, atol_scale: float) -> tuple[float, float]:
    """(largest |x - y| beyond its tolerance, that |x - y|); (0, 0) within tolerance. NaN == NaN."""
    with np.errstate(invalid='ignore'):
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        diff = np.where(same, 0.0, np.abs(x - y))
    diff = np.where(np.isnan(diff), np.inf, diff)          # NaN against a number
    scale = np.max(np.abs(np.where(np.isfinite(x), x, 0.0)), initial=0.0)
    allowed = atol_scale * scale + rtol * np.abs(np.where(np.isfinite(y), y, 0.0))
    over = diff - allowed
    if diff.size == 0 or np.max(over) <= 0.0:
        return 0.0, 0.0
    i = np.unravel_index(np.argmax(over), over.shape)
    return float(over[i]), float(diff[i])
