"""Declare a node's parameters from ParamSpecs, with descriptors; one clear error for bad files;
and the `main()` both node executables share."""
from __future__ import annotations

import faulthandler
import math
import os
import re
import signal
import sys
import tempfile

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from .executors import EXECUTORS, executor_problem, make_executor, spin_once_args
from .param_files import files_not_applying, keys_addressed_to
from .parameters import (DELIVERY_WAIT_S, RENAMED, RETIRED, ParameterFileError, ParamSpec, allowed_range, check_value,
                         config_from_params, renamed_values)

__all__ = ['ParameterFileError', 'await_delivery', 'check_known', 'declare_parameters', 'delivery_wait_s', 'first_problem',
           'parameter_file_problems', 'run_node']

_RCLPY_OWN = {'use_sim_time', 'start_type_description_service'}


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    rng = allowed_range(spec)
    if rng is not None:
        d.additional_constraints = f'allowed: {rng}' + (' (each value)' if spec.unset_array else '')
    if spec.unset_array:
        # A list of numbers that may stay unset. Declared without a value and with dynamic typing: an
        # empty default would be typed as a byte array by rclpy and refuse the list of floats a
        # params file gives (check_value keeps it a list of numbers).
        d.type = ParameterType.PARAMETER_DOUBLE_ARRAY
        d.dynamic_typing = True
        return d
    if spec.min_value is None or isinstance(spec.default, bool):
        return d
    # ROS ranges are inclusive: a strict bound (min_exclusive) is enforced by check_value
    if isinstance(spec.default, float) and not math.isnan(spec.default):
        # (NaN means "unset" and fails ROS range checks: such parameters are checked in check_value)
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.min_value), to_value=float(spec.max_value))]
    elif isinstance(spec.default, int):
        d.integer_range = [IntegerRange(from_value=int(spec.min_value), to_value=int(spec.max_value), step=1)]
    return d


def declare_parameters(node, specs: dict[str, ParamSpec]) -> dict:
    """Declare every spec on the node; returns the values in force (defaults or overrides)."""
    # rclpy keeps --params-file / parameter_overrides values here until they are declared.
    _rename_overrides(node)
    _check_unknown(node, set(getattr(node, '_parameter_overrides', {})) - set(specs) - _RCLPY_OWN)
    values = {}
    for spec in specs.values():
        override = getattr(node, '_parameter_overrides', {}).get(spec.name)
        problem = None if override is None else check_value(spec, override.value)
        if problem:   # our reason (with strict bounds) rather than rclpy's
            raise ParameterFileError(problem)
        try:
            default = None if spec.unset_array else spec.default
            value = node.declare_parameter(spec.name, default, _descriptor(spec)).value
        except Exception as exc:  # wrong type or out of range in a params file
            raise ParameterFileError(f'parameter {spec.name}: {exc}') from None
        problem = check_value(spec, value)
        if problem:
            raise ParameterFileError(problem)
        values[spec.name] = value
    return values


def _rename_overrides(node) -> None:
    """Values given under a parameter's old name (parameters.RENAMED) move to its new name,
    converted; the node says so once per name."""
    from rclpy.parameter import Parameter
    overrides = getattr(node, '_parameter_overrides', {})
    if not any(name in overrides for name in RENAMED):
        return
    values, notes = renamed_values({name: p.value for name, p in overrides.items()})
    for old, (new, _) in RENAMED.items():
        if old in overrides:
            del overrides[old]
            overrides[new] = Parameter(new, value=values[new])
    for note in notes:
        node.get_logger().warning(note)


def _check_unknown(node, unknown: set[str]) -> None:
    """Unknown keys addressed to this node by name stop it (a typo would silently change nothing);
    keys it got from a wildcard section (a robot-wide `/**` file) are another node's: said once, ignored."""
    retired = sorted(unknown & set(RETIRED))
    for key in retired:
        node.get_logger().warning(f'ignoring parameter {key}: retired, {RETIRED[key]}')
    unknown = unknown - set(RETIRED)
    if not unknown:
        return
    addressed = keys_addressed_to(node.get_fully_qualified_name(), _global_args())
    mine = sorted(k for k in unknown if k in addressed)
    if mine:
        where = '; '.join(f'{k} ({addressed[k]})' for k in mine)
        raise ParameterFileError(f'unknown parameter(s) for {node.get_name()}: {where}')
    node.get_logger().warning(f'ignoring parameter(s) this node does not have (from a shared section): '
                              f'{", ".join(sorted(unknown))}')


def parameter_file_problems(node) -> list[str]:
    """The parameter files given to this process of which no section applies to `node` (their
    values never reach it), each said once in the log; the node keeps them for its diagnostics."""
    problems = files_not_applying(node.get_fully_qualified_name(), _global_args())
    for problem in problems:
        node.get_logger().warning(problem)
    return problems


def check_known(params: dict, specs, node_name: str) -> None:
    """Values a script hands one node by name (compose.make_*): each must be one of its parameters."""
    unknown = sorted(set(params) - {s.name for s in specs} - _RCLPY_OWN - set(RETIRED) - set(RENAMED))
    if unknown:
        raise ParameterFileError(f'unknown parameter(s) for {node_name}: {", ".join(unknown)}')


def _global_args() -> list[str]:
    """The process-wide ROS arguments: what run_node gave rclpy.init, else sys.argv (rclpy's default)."""
    return _GLOBAL_ARGS if _GLOBAL_ARGS is not None else sys.argv


_GLOBAL_ARGS: list[str] | None = None


def first_problem(specs: dict[str, ParamSpec], params, current: dict | None = None, base=None) -> str | None:
    """Why a set-parameters request must be refused (the first reason), or None.

    Each value is checked against its spec (type, range, strict bounds). With `current` (the node's
    values in force, name -> value) the config the change would give is checked as a whole too
    (e.g. gate.mismatch_smooth_s < gate.mismatch_window_s): `base` is the config the values fill in
    (default EstimatorConfig())."""
    for p in params:
        spec = specs.get(p.name)
        if spec is not None:
            problem = check_value(spec, p.value)
            if problem:
                return problem
    if current is not None and any(p.name in specs for p in params):
        merged = {**current, **{p.name: p.value for p in params if p.name in specs}}
        try:
            config_from_params(merged, base)
        except ParameterFileError as exc:
            return str(exc)
    return None


def run_node(node_class, executable: str, args=None) -> int:
    """Entry point of a node executable: bad parameters -> one line and exit 2; Ctrl-C -> the node
    processes what it buffered, saves its state, and exits 0; SIGTERM (systemd, docker stop) likewise."""
    import rclpy
    import rclpy.executors
    import rclpy.signals
    # Our own Ctrl-C handling: rclpy's would invalidate the context before the last batch is published.
    global _GLOBAL_ARGS
    _GLOBAL_ARGS = list(args) if args is not None else None
    # `kill -USR1 <pid>` prints every thread's stack: where a node that does not stop is stuck.
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    kind, problem = _executor_choice(args)
    problem = problem or _init(rclpy, args)   # rclpy.init without its signal handlers
    if problem:
        print(f'{executable}: error: {problem}', file=sys.stderr)
        return 2
    # SIGINT/SIGTERM while starting wait until the node exists, then stop it: rclpy.spin by a
    # KeyboardInterrupt, the events loop below at its next turn (never inside a callback: the
    # EventsExecutor would log the exception and carry on)
    stop = _StopSignals(interrupt=kind == 'single')
    try:
        node = node_class()
    except ParameterFileError as exc:
        print(f'{executable}: error: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        stop.node_ready()
        if kind == 'single':
            rclpy.spin(node)
        else:
            executor = make_executor(kind, node.context)
            executor.add_node(node)
            while executor.context.ok() and not stop.requested:
                executor.spin_once(**spin_once_args(kind))
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.shutdown()
        await_delivery(node, delivery_wait_s(node))
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _executor_choice(args) -> tuple[str, str | None]:
    """The executable's own arguments (before --ros-args): `--executor single|events`. Returns the
    executor kind and None, or a one-line problem."""
    own, in_ros = [], False
    for arg in (list(args) if args is not None else sys.argv)[1:]:
        # rcl's own split (rclpy.utilities.remove_ros_args) also parses what follows --ros-args
        # and would raise on a bad parameter file, which _init turns into one line
        if arg == '--ros-args':
            in_ros = True
        elif in_ros and arg == '--':
            in_ros = False
        elif not in_ros:
            own.append(arg)
    kind = 'single'
    while own:
        arg = own.pop(0)
        name, _, value = arg.partition('=')
        if name != '--executor':
            return kind, (f'unknown argument {arg!r} (the node takes --executor {{{",".join(EXECUTORS)}}}; '
                          'ROS arguments follow --ros-args)')
        if not value:
            value = own.pop(0) if own else ''
        problem = executor_problem(value)
        if problem:
            return kind, problem
        kind = value
    return kind, None


def _init(rclpy, args) -> str | None:
    """rclpy.init; None, or one line saying why the ROS arguments cannot be used (a parameter file
    that is missing or not YAML: rcl parses --params-file here). rcl also logs the failure on
    stderr from C ("Failed to parse global arguments"); that is held back so the user reads one line.
    rclpy's own signal handlers stay off: ours let the node publish its last batch (run_node)."""
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
            error = None
        except _rclpy.RCLError as exc:
            error = str(exc)
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        if error is None:
            held.seek(0)
            text = held.read()
            if text:   # whatever rcl said while starting up successfully
                os.write(2, text)
            return None
    m = re.search(r"Couldn't parse params file: '--params-file (.*?)'\. Error: (.*)", error)
    if m:
        return f'cannot read parameter file {m.group(1)}: {_params_file_problem(m.group(1), m.group(2))}'
    return f'invalid ROS arguments: {_strip_locations(error)}'


def _strip_locations(message: str) -> str:
    """rcl's error text without its ', at /path/file.c:123' trail."""
    return re.sub(r',? at \S+:\d+', '', message).strip()


def _params_file_problem(path: str, rcl_message: str) -> str:
    """What is wrong with a parameter file rcl could not parse: YAML's own words (with the line)
    when it is not YAML at all, else rcl's (e.g. a list mixing integers and floats)."""
    try:
        import yaml
    except ImportError:
        return _strip_locations(rcl_message)
    try:
        with open(path, encoding='utf-8') as fh:
            yaml.safe_load(fh)
    except OSError as exc:
        return exc.strerror or str(exc)
    except yaml.MarkedYAMLError as exc:
        where = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context or 'not valid YAML'
        return f'not valid YAML: line {where.line + 1}: {what}' if where else f'not valid YAML: {what}'
    except (yaml.YAMLError, ValueError) as exc:   # other YAML errors (e.g. not UTF-8)
        return f'not valid YAML: {exc}'.splitlines()[0]
    return _strip_locations(rcl_message)


class _StopSignals:
    """SIGINT and SIGTERM (systemd, docker stop) end the spin with KeyboardInterrupt, so the node
    flushes and saves its state (SIGTERM's default would kill the process and lose up to
    state_save_period_s of learning). One that arrives while the node is being built is held until
    it exists: a node half built cannot save, a built one can. Installed even over an inherited
    SIG_IGN, as rclpy does: a node started from a background job (`cmd &` ignores SIGINT) must still
    stop when ros2 launch or a supervisor sends it SIGINT."""

    def __init__(self, interrupt: bool = True):
        self._ready, self._pending = False, False
        self._interrupt = interrupt   # else a signal once the node is ready only sets `requested`
        self.requested = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handler)

    def _handler(self, signum, frame):
        if not self._ready:
            self._pending = True
            return
        self.requested = True
        if self._interrupt:
            raise KeyboardInterrupt(f'signal {signum}')

    def node_ready(self) -> None:
        self._ready = True
        if self._pending:
            raise KeyboardInterrupt('signal while starting')


def delivery_wait_s(node) -> float:
    """How long a stopping node waits for acknowledgements: its `stop_delivery_wait_s` parameter
    where it has one."""
    return float(getattr(node, 'settings', {}).get('stop_delivery_wait_s', DELIVERY_WAIT_S))


def await_delivery(node, timeout_s: float = DELIVERY_WAIT_S) -> None:
    """Let reliable subscribers acknowledge what the node published while shutting down: the
    process exits next, and samples still in the writer's queue would be lost with it. One budget
    for all publishers, so a stop never takes longer than `timeout_s` for this."""
    import time
    from rclpy.duration import Duration
    end = time.monotonic() + timeout_s
    for publisher in node.publishers:
        left_s = max(0.0, end - time.monotonic())
        try:
            publisher.wait_for_all_acked(Duration(seconds=left_s))
        except RuntimeError as exc:  # the context is already closing: exit anyway
            node.get_logger().debug(f'not waiting for {publisher.topic_name} acknowledgements: {exc}')
