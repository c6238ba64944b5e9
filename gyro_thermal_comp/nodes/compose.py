"""Several nodes in one process, no launch file: build them with parameters, spin them together.

    import rclpy
    from gyro_thermal_comp.nodes.compose import make_stkf_node, make_carousel_node, spin_together
    rclpy.init()
    stkf = make_stkf_node({'window_s': 10.0, 'state_file': '/var/lib/gtc/stkf.json'},
                          remap={'imu/data_raw': '/vehicle/imu/raw'})
    carousel = make_carousel_node(namespace='wheel')
    spin_together(stkf, carousel)          # MultiThreadedExecutor; Ctrl-C saves state and shuts down
"""
from __future__ import annotations

from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.parameter import Parameter


def _node_kwargs(params: dict | None, namespace: str, remap: dict | None) -> dict:
    cli_args = []
    for src, dst in (remap or {}).items():
        cli_args += ['-r', f'{src}:={dst}']
    return {'namespace': namespace,
            'parameter_overrides': [Parameter(k, value=v) for k, v in (params or {}).items()],
            'cli_args': ['--ros-args', *cli_args] if cli_args else None}


def make_stkf_node(params: dict | None = None, *, name: str = 'stkf_drift_estimator', namespace: str = '',
                   remap: dict | None = None):
    """The STKF node with parameter values (as in config/stkf.yaml) and topic remappings."""
    from .stkf_node import StkfDriftEstimatorNode
    return StkfDriftEstimatorNode(name, **_node_kwargs(params, namespace, remap))


def make_carousel_node(params: dict | None = None, *, name: str = 'carousel_demodulator', namespace: str = '',
                       remap: dict | None = None):
    """The carousel demodulator node with parameter values and topic remappings."""
    from .carousel_node import CarouselDemodulatorNode
    return CarouselDemodulatorNode(name, **_node_kwargs(params, namespace, remap))


def spin_together(*nodes, executor=None, timeout_sec: float | None = None) -> None:
    """Spin the nodes in one executor until shutdown (or for `timeout_sec`), then save and destroy them."""
    executor = executor or MultiThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    try:
        if timeout_sec is None:
            executor.spin()
        else:
            import time
            end = time.monotonic() + timeout_sec
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=min(0.1, max(0.0, end - time.monotonic())))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            getattr(node, 'shutdown', lambda: None)()
            executor.remove_node(node)
            node.destroy_node()
