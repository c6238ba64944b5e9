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


def executor_problem(kind) -> str | None:
    """None, or one line saying why `kind` names no executor."""
    return None if kind in EXECUTORS else f"--executor must be one of {', '.join(EXECUTORS)}, not {kind!r}"


def make_executor(kind: str = 'single', context=None):
    """An executor of `kind` (one of EXECUTORS) for `context` (rclpy's default when None)."""
    problem = executor_problem(kind)
    if problem:
        raise ValueError(problem)
    if kind == 'single':
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def spin_once_args(kind: str) -> dict:
    """The arguments of `spin_once` for a loop that checks a stop flag between turns: rclpy's
    SingleThreadedExecutor none (a timeout costs a timer per turn; a node's own timers wake it), the
    EventsExecutor a 0.1 s timeout (its wait in C++ does not return for a signal)."""
    return {} if kind == 'single' else {'timeout_sec': 0.1}
