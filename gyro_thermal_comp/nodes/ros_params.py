"""Declare a node's parameters from ParamSpecs, with descriptors; one clear error for bad files;
and the `main()` both node executables share."""
from __future__ import annotations

import math
import sys

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from .parameters import ParamSpec, check_value

_RCLPY_OWN = {'use_sim_time', 'start_type_description_service'}


class ParameterFileError(RuntimeError):
    """A parameter file with unknown keys, wrong types or out-of-range values: one line at start-up."""


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.min_value is None or isinstance(spec.default, bool):
        return d
    if isinstance(spec.default, float) and not math.isnan(spec.default):
        # (NaN means "unset" and fails ROS range checks: such parameters are checked in check_value)
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.min_value), to_value=float(spec.max_value))]
    elif isinstance(spec.default, int):
        d.integer_range = [IntegerRange(from_value=int(spec.min_value), to_value=int(spec.max_value), step=1)]
    return d


def declare_parameters(node, specs: dict[str, ParamSpec]) -> dict:
    """Declare every spec on the node; returns the values in force (defaults or overrides)."""
    # rclpy keeps --params-file / parameter_overrides values here until they are declared.
    overrides = set(getattr(node, '_parameter_overrides', {}))
    unknown = sorted(overrides - set(specs) - _RCLPY_OWN)
    if unknown:
        raise ParameterFileError(f'unknown parameter(s) for {node.get_name()}: {", ".join(unknown)}')
    values = {}
    for spec in specs.values():
        try:
            value = node.declare_parameter(spec.name, spec.default, _descriptor(spec)).value
        except Exception as exc:  # wrong type or out of range in a params file
            raise ParameterFileError(f'parameter {spec.name}: {exc}') from None
        problem = check_value(spec, value)
        if problem:
            raise ParameterFileError(problem)
        values[spec.name] = value
    return values


def first_problem(specs: dict[str, ParamSpec], params) -> str | None:
    """Why a set-parameters request must be refused (the first reason), or None."""
    for p in params:
        spec = specs.get(p.name)
        if spec is not None:
            problem = check_value(spec, p.value)
            if problem:
                return problem
    return None


def run_node(node_class, executable: str, args=None) -> int:
    """Entry point of a node executable: bad parameters -> one line and exit 2; Ctrl-C -> the node
    processes what it buffered, saves its state, and exits 0."""
    import rclpy
    import rclpy.executors
    import rclpy.signals
    # Our own Ctrl-C handling: rclpy's would invalidate the context before the last batch is published.
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        node = node_class()
    except ParameterFileError as exc:
        print(f'{executable}: error: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.shutdown()
        _await_delivery(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _await_delivery(node, timeout_s: float = 5.0) -> None:
    """Let reliable subscribers acknowledge what the node published while shutting down: the
    process exits next, and samples still in the writer's queue would be lost with it."""
    from rclpy.duration import Duration
    for publisher in node.publishers:
        try:
            publisher.wait_for_all_acked(Duration(seconds=timeout_s))
        except RuntimeError as exc:  # the context is already closing: exit anyway
            node.get_logger().debug(f'not waiting for {publisher.topic_name} acknowledgements: {exc}')
