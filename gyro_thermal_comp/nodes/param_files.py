"""Which parameters the ROS arguments address to one node by its name, and which parameter files
say nothing to it.

A robot shares one params file between many nodes: values under `/**` (or any wildcard) go to every
node, and ROS practice is that a node ignores what it does not declare. A key under a section that
ends in this node's own name (`stkf_drift_estimator`, `/robot1/stkf_drift_estimator`,
`/**/stkf_drift_estimator`), or `-p <node>:<key>:=...`, was meant for this node: unknown, it is a
typo worth stopping for. rclpy merges all of them into one override dict, so the arguments are read
again here, with rcl's matching of section names: a name without a leading `/` is in the root
namespace, `*` stands for one namespace token or the node name, `/**` for any number of namespace
tokens (none included). A file none of whose sections applies to the node (the package's own file
written as `stkf_drift_estimator:` and the node started in a namespace) would change nothing
without a word: `files_not_applying` names it.
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


def section_applies(section: str, node_fqn: str) -> bool:
    """Whether a params-file section name (or a `-p node:` prefix) applies to the node `node_fqn`
    ('/ns/name'), as rcl matches them (`*`: one token, `/**`: any number of namespace tokens)."""
    want = _absolute(section).strip('/').split('/')
    have = _absolute(node_fqn).strip('/').split('/')

    def match(i: int, j: int) -> bool:
        if i == len(want):
            return j == len(have)
        if want[i] == '**':   # last: every node; else namespace tokens, the node name still to follow
            return i + 1 == len(want) or any(match(i + 1, k) for k in range(j, len(have)))
        return j < len(have) and (want[i] == '*' or want[i] == have[j]) and match(i + 1, j + 1)
    return match(0, 0)


def _by_name(section: str, node_fqn: str) -> bool:
    """The section applies to the node and names it: its last token is the node's own name."""
    own_name = node_fqn.rsplit('/', 1)[-1]
    return section_applies(section, node_fqn) and section.rstrip('/').rsplit('/', 1)[-1] == own_name


def _params_files(args: Sequence[str]):
    """(path, its sections) of every readable `--params-file` in the ROS arguments."""
    import yaml
    for flag, value in ros_arguments(args):
        if flag != '--params-file':
            continue
        try:
            with open(value, encoding='utf-8') as fh:
                tree = yaml.safe_load(fh)
        except (OSError, ValueError, yaml.YAMLError):
            continue   # rcl's to report (rclpy.init)
        yield value, list(_file_sections(tree))


def keys_addressed_to(node_fqn: str, args: Sequence[str]) -> dict[str, str]:
    """{parameter: where it was given} for the keys addressed to the node `node_fqn` ('/ns/name') by
    its own name, not by a wildcard in its place. Files that cannot be read are rcl's to report
    (rclpy.init)."""
    fqn, addressed = _absolute(node_fqn), {}
    for flag, value in ros_arguments(args):
        if flag == '-p':
            node, sep, rest = value.partition(':')
            if sep and not node.startswith('=') and ':=' in rest and _by_name(node, fqn):
                addressed[rest.split(':=', 1)[0]] = f'-p {value}'
    for value, sections in _params_files(args):
        for path, params in sections:
            if _by_name(path, fqn):
                addressed.update(dict.fromkeys(_flatten(params), f'{value} under {path.lstrip("/")}'))
    return addressed


def files_not_applying(node_fqn: str, args: Sequence[str]) -> list[str]:
    """One sentence per parameter file of which no section applies to the node `node_fqn`: none of
    its values reach it."""
    fqn, out = _absolute(node_fqn), []
    name = fqn.rsplit('/', 1)[-1]
    for value, sections in _params_files(args):
        if sections and not any(section_applies(path, fqn) for path, _ in sections):
            names = ', '.join(path.lstrip('/') for path, _ in sections)
            out.append(f'parameter file {value}: no section applies to {fqn} (sections: {names}), so none of its '
                       f'values are used; name the section /**/{name} (any namespace) or {fqn}')
    return out
