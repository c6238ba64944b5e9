"""Which parameters the ROS arguments address to one node by its name.

A robot shares one params file between many nodes: values under `/**` (or any wildcard) go to every
node, and ROS practice is that a node ignores what it does not declare. A key under this node's own
name, or `-p <node>:<key>:=...`, was meant for this node: unknown, it is a typo worth stopping for.
rclpy merges all of them into one override dict, so the arguments are read again here.
"""
from __future__ import annotations

from collections.abc import Sequence

# ROS arguments that take one value (after --ros-args), besides the two read here.
_WITH_VALUE = {'-r', '--remap', '-e', '--enclave', '--log-level', '--log-config-file', '--log-file-name'}


def ros_arguments(args: Sequence[str]) -> list[tuple[str, str]]:
    """(flag, value) of every `--params-file` and `-p/--param` inside the `--ros-args` scopes."""
    found, in_ros, i = [], False, 0
    while i < len(args):
        arg = args[i]
        if arg == '--ros-args':
            in_ros = True
        elif arg == '--':
            in_ros = False
        elif in_ros and arg in ('--params-file', '-p', '--param') and i + 1 < len(args):
            found.append(('--params-file' if arg == '--params-file' else '-p', args[i + 1]))
            i += 1
        elif in_ros and arg in _WITH_VALUE:
            i += 1
        i += 1
    return found


def _absolute(name: str) -> str:
    return name if name.startswith('/') else '/' + name


def _flatten(params: dict, prefix: str = '') -> list[str]:
    keys = []
    for key, value in params.items():
        name = f'{prefix}{key}'
        keys += _flatten(value, name + '.') if isinstance(value, dict) else [name]
    return keys


def _file_sections(tree, path: str = ''):
    """(node path, its ros__parameters) of a params file, nested namespaces joined with '/'."""
    if not isinstance(tree, dict):
        return
    for key, value in tree.items():
        if key == 'ros__parameters' and isinstance(value, dict):
            yield path, value
        elif isinstance(value, dict):
            yield from _file_sections(value, f'{path}/{str(key).strip("/")}')


def keys_addressed_to(node_fqn: str, args: Sequence[str]) -> dict[str, str]:
    """{parameter: where it was given} for the keys addressed to the node `node_fqn` ('/ns/name') by
    its own name, not by a wildcard. Files that cannot be read are rcl's to report (rclpy.init)."""
    import yaml
    fqn, addressed = _absolute(node_fqn), {}
    for flag, value in ros_arguments(args):
        if flag == '-p':
            node, sep, rest = value.partition(':')
            if sep and not node.startswith('=') and ':=' in rest and _absolute(node) in (fqn, '/' + fqn.rsplit('/', 1)[1]):
                addressed[rest.split(':=', 1)[0]] = f'-p {value}'
            continue
        try:
            with open(value, encoding='utf-8') as fh:
                tree = yaml.safe_load(fh)
        except (OSError, ValueError, yaml.YAMLError):
            continue
        for path, params in _file_sections(tree):
            if '*' not in path and _absolute(path) == fqn:
                addressed.update(dict.fromkeys(_flatten(params), f'{value} under {path.lstrip("/")}'))
    return addressed
