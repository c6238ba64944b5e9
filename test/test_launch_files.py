"""The launch files name only real executables, node names, topics and parameter files.

`launch`/`launch_ros` are not installable from PyPI, so each file runs here against small stand-ins
that record what it builds; where the real packages exist, the file is also built with them.
"""
import importlib.util
import re
import sys
import types
from types import SimpleNamespace
from pathlib import Path

import pytest
import yaml

from conftest import REPO
from gyro_thermal_comp.nodes.interface import NODES

LAUNCH_FILES = sorted((REPO / 'launch').glob('*.launch.py'))


class _Recorded:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class LaunchConfiguration(_Recorded):
    used: set = set()

    def __init__(self, name):
        super().__init__(name)
        LaunchConfiguration.used.add(name)


def _stand_ins() -> dict:
    """Modules `launch*` as the files import them, each class recording its arguments."""
    mods = {name: types.ModuleType(name) for name in ('launch', 'launch.actions', 'launch.substitutions',
                                                       'launch_ros', 'launch_ros.actions',
                                                       'launch_ros.substitutions')}
    mods['launch'].LaunchDescription = _Recorded
    mods['launch.actions'].DeclareLaunchArgument = type('DeclareLaunchArgument', (_Recorded,), {})
    mods['launch.actions'].OpaqueFunction = type('OpaqueFunction', (_Recorded,), {})
    mods['launch.substitutions'].LaunchConfiguration = LaunchConfiguration
    mods['launch.substitutions'].PathJoinSubstitution = type('PathJoinSubstitution', (_Recorded,), {})
    mods['launch_ros.actions'].Node = type('Node', (_Recorded,), {})
    mods['launch_ros.substitutions'].FindPackageShare = type('FindPackageShare', (_Recorded,), {})
    return mods


def _build(path: Path, monkeypatch):
    for name, mod in _stand_ins().items():
        monkeypatch.setitem(sys.modules, name, mod)
    LaunchConfiguration.used = set()
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def _declared(description) -> dict:
    return {a.args[0]: a.kwargs for a in description.args[0] if type(a).__name__ == 'DeclareLaunchArgument'}


def _resolve(value, configs: dict):
    """A value with the launch configurations (stand-ins) it refers to replaced by their values."""
    if isinstance(value, LaunchConfiguration):
        return configs[value.args[0]]
    if isinstance(value, dict):
        return {k: _resolve(v, configs) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_resolve(v, configs) for v in value)
    return value


def _nodes(description, given: dict | None = None) -> list[dict]:
    """The Node actions the launch file starts with these command-line arguments (name -> string),
    as launch runs it: each declared argument holds the value given, else its default; actions
    built at launch time (OpaqueFunction) are built with them."""
    configs = {name: (given or {}).get(name, d['default_value']) for name, d in _declared(description).items()}
    nodes = []
    for action in description.args[0]:
        if type(action).__name__ == 'OpaqueFunction':
            built = action.kwargs['function'](SimpleNamespace(launch_configurations=dict(configs)))
            nodes += [a for a in built if type(a).__name__ == 'Node']
        elif type(action).__name__ == 'Node':
            nodes.append(action)
    return [_resolve(n.kwargs, configs) for n in nodes]


def _console_scripts() -> set[str]:
    return set(re.findall(r"'(\w[\w-]*) = gyro_thermal_comp", (REPO / 'setup.py').read_text()))


def test_there_is_a_launch_file_per_node():
    assert {p.name for p in LAUNCH_FILES} == {f'{k}.launch.py' for k in NODES}


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_names_real_things(path, monkeypatch):
    description = _build(path, monkeypatch)
    declared = _declared(description)
    nodes = _nodes(description)
    assert len(nodes) == 1
    node = nodes[0]
    interface = NODES[path.name.split('.')[0]]
    assert node['package'] == 'gyro_thermal_comp'
    assert node['executable'] in _console_scripts() and node['executable'] == interface.executable
    assert node['name'] == interface.node_name
    assert LaunchConfiguration.used <= set(declared), 'a launch argument is used but not declared'
    topics = {p.topic for p in interface.inputs + interface.outputs}
    every_remap = _nodes(description, {name: f'/robot/{name}' for name, d in declared.items()
                                       if d['default_value'] == ''})[0]['remappings']
    assert every_remap and {src for src, _ in every_remap} <= topics, 'remaps a topic the node does not have'
    for arg in declared.values():
        assert arg['description'] and arg['default_value'] is not None
    # The default parameters file is one of the package's config files, for this node.
    defaults = [a['default_value'] for a in declared.values()]
    joined = [d for d in defaults if type(d).__name__ == 'PathJoinSubstitution'][0].args[0]
    assert joined[0].args == ('gyro_thermal_comp',) and joined[1] == 'config'
    name = joined[2] if isinstance(joined[2], str) else declared[joined[2].args[0]]['default_value']
    config = yaml.safe_load((REPO / 'config' / name).read_text())
    assert list(config) == [f'/**/{interface.node_name}']    # the node in any namespace


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_a_launch_file_passes_only_the_arguments_given(path, monkeypatch):
    """A robot's params file holds its state_file and use_sim_time: a launch argument left out must
    not override them with the launch file's defaults (parameters later in the list win)."""
    description = _build(path, monkeypatch)
    node = _nodes(description, {'params_file': '/etc/robot/params.yaml'})[0]
    assert node['parameters'] == ['/etc/robot/params.yaml']
    assert node['remappings'] == [] and node['namespace'] == '' and not node.get('ros_arguments')
    given = {'params_file': '/etc/robot/params.yaml', 'use_sim_time': 'true', 'imu_raw': '/my_imu/data_raw',
             'namespace': 'rover1', 'log_level': 'debug'}
    if 'state_file' in _declared(description):
        given['state_file'] = '/var/lib/robot/stkf.json'
    node = _nodes(description, given)[0]
    expected = {'use_sim_time': True, **({'state_file': given['state_file']} if 'state_file' in given else {})}
    assert node['parameters'] == ['/etc/robot/params.yaml', expected]
    assert node['remappings'] == [('imu/data_raw', '/my_imu/data_raw')]
    assert node['namespace'] == 'rover1' and node['ros_arguments'] == ['--log-level', 'debug']


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_builds_with_the_real_launch_packages(path):
    pytest.importorskip('launch_ros')
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.generate_launch_description().entities
