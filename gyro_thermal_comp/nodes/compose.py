"""Several nodes in one process, no launch file: build them with parameters, spin them together.

    import rclpy
    from gyro_thermal_comp.nodes.compose import init, make_carousel_node, make_stkf_node, spin_together
    init()                                 # rclpy.init without rclpy's signal handlers
    stkf = make_stkf_node({'window_s': 10.0, 'state_file': '/var/lib/gtc/stkf.json'},
                          remap={'imu/data_raw': '/vehicle/imu/raw'})
    carousel = make_carousel_node(namespace='wheel')
    spin_together(stkf, carousel)          # Ctrl-C or SIGTERM: flush, save state, destroy; returns
    rclpy.try_shutdown()

One SingleThreadedExecutor by default. rclpy's MultiThreadedExecutor rebuilds its wait set twice
per message and hands each to a pool thread: 1.6-2.2x the dispatch CPU per input message and ~3x
the context switches (`benchmarks/executor_cost.py` measures the CPU). On two loaded cores it fell behind a 250 Hz IMU until the best-effort input queue
overflowed and samples were lost, where the single-threaded one kept up. These nodes gain nothing
from threads: their input callbacks only buffer, under the lock a batch holds, and Python runs one
callback at a time anyway (GIL). Another executor can still be passed, e.g.
`make_executor('events')` (nodes/executors.py: rclpy's EventsExecutor, experimental in Jazzy), which
spent 0.6x the CPU per IMU output of the single-threaded one at 1 kHz and kept up at 2 kHz where
it fell behind (`benchmarks/live_latency.py --executor events`, benchmarks/RESULTS.md).
"""
from __future__ import annotations

import contextlib
import faulthandler
import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.signals import (SignalHandlerOptions, get_current_signal_handlers_options, install_signal_handlers,
                           uninstall_signal_handlers)

from .ros_params import await_delivery, check_known, delivery_wait_s

__all__ = ['init', 'make_carousel_node', 'make_stkf_node', 'spin_together']

_POLL_S = 0.1   # a stop request waits at most this long for the executor's wait to return


def init(args=None) -> None:
    """rclpy.init without rclpy's signal handlers: theirs invalidate the context on Ctrl-C, before
    the nodes can publish their last batch (spin_together stops on SIGINT/SIGTERM itself).
    `kill -USR1 <pid>` prints every thread's stack (where a process that does not stop is stuck)."""
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)


def _node_kwargs(params: dict | None, namespace: str, remap: dict | None) -> dict:
    cli_args = []
    for src, dst in (remap or {}).items():
        cli_args += ['-r', f'{src}:={dst}']
    return {'namespace': namespace,
            'parameter_overrides': [Parameter(k, value=v) for k, v in (params or {}).items()],
            'cli_args': ['--ros-args', *cli_args] if cli_args else None}


def make_stkf_node(params: dict | None = None, *, name: str = 'stkf_drift_estimator', namespace: str = '',
                   remap: dict | None = None):
    """The STKF node with parameter values (as in config/stkf.yaml) and topic remappings. A name
    that is not one of its parameters is a ParameterFileError (a typo would change nothing)."""
    from .parameters import all_specs
    from .stkf_node import StkfDriftEstimatorNode
    check_known(params or {}, all_specs(), name)
    return StkfDriftEstimatorNode(name, **_node_kwargs(params, namespace, remap))


def make_carousel_node(params: dict | None = None, *, name: str = 'carousel_demodulator', namespace: str = '',
                       remap: dict | None = None):
    """The carousel demodulator node with parameter values and topic remappings (names checked)."""
    from .carousel_node import CarouselDemodulatorNode, carousel_specs
    check_known(params or {}, carousel_specs(), name)
    return CarouselDemodulatorNode(name, **_node_kwargs(params, namespace, remap))


def spin_together(*nodes, executor=None, timeout_sec: float | None = None) -> None:
    """Spin the nodes in one executor (a SingleThreadedExecutor unless given) until Ctrl-C, SIGTERM,
    rclpy shutdown or `timeout_sec`; then each node processes what it buffered, saves its state,
    waits for its reliable subscribers to acknowledge, and is destroyed. The executor is shut down.

    Signals end the spin between two callbacks (never inside one, which could leave a batch half
    published or the filter half updated); rclpy's own handlers, if installed, are set aside meanwhile."""
    if executor is None:
        executor = SingleThreadedExecutor(context=nodes[0].context if nodes else None)
    for node in nodes:
        executor.add_node(node)
    with _stop_signals() as stop:
        try:
            end = None if timeout_sec is None else time.monotonic() + timeout_sec
            while not stop.is_set() and executor.context.ok():
                wait_s = _POLL_S if end is None else min(_POLL_S, end - time.monotonic())
                if wait_s <= 0.0:
                    break
                executor.spin_once(timeout_sec=wait_s)
        except (KeyboardInterrupt, ExternalShutdownException):   # not the main thread; rclpy shut down elsewhere
            pass
        finally:
            _finish(executor, nodes)


@contextlib.contextmanager
def _stop_signals():
    """An Event set by SIGINT and SIGTERM while the block runs; previous handlers restored after.
    A handler of the script's own is kept; an inherited SIG_IGN is not (a background job `cmd &`
    ignores SIGINT, and ros2 launch stops processes with SIGINT, as rclpy knows). Signals are the
    main thread's only."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    rclpy_handlers = get_current_signal_handlers_options()
    if rclpy_handlers != SignalHandlerOptions.NO:
        uninstall_signal_handlers()
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig, handler in previous.items():
        if handler in (signal.default_int_handler, signal.SIG_DFL, signal.SIG_IGN):
            signal.signal(sig, lambda signum, frame: stop.set())
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if rclpy_handlers != SignalHandlerOptions.NO:
            install_signal_handlers(rclpy_handlers)


def _finish(executor, nodes) -> None:
    """No callback runs any more; each node flushes and saves, its outputs are delivered, it goes.
    A failure of one node does not keep the others from saving; the first is raised at the end."""
    pool = getattr(executor, '_executor', None)
    if isinstance(pool, ThreadPoolExecutor):
        # MultiThreadedExecutor: rclpy 7.1's Executor.shutdown does not wait for callbacks in flight
        # (it means to). Let a running one end and drop the queued ones before the nodes flush.
        pool.shutdown(wait=True, cancel_futures=True)
    for node in nodes:
        executor.remove_node(node)
    errors = []
    for node in nodes:
        try:
            if node.context.ok():
                getattr(node, 'shutdown', lambda: None)()
            else:   # rclpy shut down elsewhere: nothing can be published, the state can still be saved
                getattr(node, 'save_state', lambda: None)()
        except Exception as exc:  # noqa: BLE001 (the other nodes must still save and be destroyed)
            node.get_logger().error(f'shutdown failed: {exc}')
            errors.append(exc)
    for node in nodes:
        if node.context.ok():
            await_delivery(node, delivery_wait_s(node))
    for node in nodes:
        node.destroy_node()
    executor.shutdown()
    if errors:
        raise errors[0]
