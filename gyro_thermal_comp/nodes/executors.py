"""Which rclpy executor spins a node process: `single` (rclpy's SingleThreadedExecutor, the default)
or `events` (rclpy.experimental.EventsExecutor: the middleware fills a C++ event queue, no wait set
is rebuilt per message).

rclpy's SingleThreadedExecutor spent about 0.5 ms of CPU per message here, more than the node's own
work per IMU sample; the EventsExecutor about 0.2 ms (`benchmarks/live_latency.py`, both
executors in benchmarks/RESULTS.md). It is marked experimental in Jazzy (a callback that takes the
message info fails on it; the nodes take none), so it is a choice (`stkf_node --executor events`),
not the default.
"""
from __future__ import annotations

EXECUTORS = ('single', 'events')


def make_executor(kind: str = 'single', context=None):
    """An executor of `kind` (one of EXECUTORS) for `context` (rclpy's default when None)."""
    if kind == 'single':
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, not {kind!r}")
