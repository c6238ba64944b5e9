"""The README's two commands, .ci/run and the ament_python layout agree with each other."""
import ast
import configparser
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from conftest import REPO


def _readme_commands():
    readme = (REPO / 'README.md').read_text()
    return re.findall(r'^\s*(make \w+)\s*$', readme, flags=re.MULTILINE)


def test_readme_gives_demo_and_test_commands():
    commands = _readme_commands()
    assert 'make demo' in commands and 'make test' in commands


def test_ci_runs_the_readme_test_command():
    ci_lines = [ln.strip() for ln in (REPO / '.ci' / 'run').read_text().splitlines()
                if ln.strip() and not ln.lstrip().startswith('#')]
    assert 'make test' in _readme_commands()
    assert 'make test' in ci_lines


def test_package_xml_is_format_3_with_runtime_deps():
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == 'gyro_thermal_comp'
    deps = {e.text for e in root.findall('exec_depend')}
    assert {'rclpy', 'sensor_msgs', 'geometry_msgs', 'nav_msgs', 'diagnostic_msgs', 'std_msgs'} <= deps
    assert root.find('export/build_type').text == 'ament_python'


def _third_party_imports(paths) -> set[str]:
    names = set()
    for path in paths:
        for node in ast.walk(ast.parse(Path(path).read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split('.')[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - {'gyro_thermal_comp'}


def _imported_top_level() -> set[str]:
    return _third_party_imports((REPO / 'gyro_thermal_comp').rglob('*.py'))


def _node_imports() -> set[str]:
    """What the modules `stkf_node` and `carousel_node` load import (their own source, every import)."""
    code = ('import sys, gyro_thermal_comp.nodes.stkf_node, gyro_thermal_comp.nodes.carousel_node\n'
            'print("\\n".join(m.__file__ for n, m in list(sys.modules.items())'
            ' if n.startswith("gyro_thermal_comp") and getattr(m, "__file__", None)))')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return _third_party_imports(proc.stdout.split())


# import name -> rosdep key / pip name, where they differ
_ROSDEP = {'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
           'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm'}
_PIP = {'dask': 'distributed'}   # `dask.distributed` comes with the distributed package


def _requirement_names(name: str) -> set[str]:
    return {re.split(r'[<>=\[ ]', ln)[0].strip().lower()
            for ln in (REPO / name).read_text().splitlines() if ln.strip() and ln[0] not in '#-'}


def _exec_depends() -> set[str]:
    return {e.text for e in ET.parse(REPO / 'package.xml').getroot().findall('exec_depend')}


def test_every_imported_package_is_declared_for_rosdep_or_pip():
    """A workspace on an apt-installed Jazzy gets each import from package.xml (rosdep) or from
    requirements-robot.txt / requirements-tools.txt (pip, no rosdep key), never from neither."""
    deps = _exec_depends()
    pip = _requirement_names('requirements-robot.txt') | _requirement_names('requirements-tools.txt')
    missing = sorted(name for name in _imported_top_level()
                     if _ROSDEP.get(name, name) not in deps and name.lower() not in pip)
    assert not missing, f'imported but neither in package.xml nor a requirements file: {missing}'
    assert not any(p.startswith('ros-') or p in ('numpy', 'rclpy') for p in pip), 'would shadow the system ROS'


def test_robot_run_dependencies_are_what_the_nodes_import():
    """package.xml's Python run dependencies and requirements-robot.txt are the nodes' imports (scipy
    for filterpy): the plotting, progress-bar, log-format and cluster packages of the offline tools
    are in requirements-tools.txt only."""
    used = _node_imports()
    robot = _requirement_names('requirements-robot.txt')
    python_deps = {d for d in _exec_depends() if d.startswith('python3-')}
    assert robot == {n for n in used if _ROSDEP.get(n, n) not in _exec_depends()}
    assert python_deps == {_ROSDEP[n] for n in used if n in _ROSDEP} | {'python3-scipy'}
    tools = _requirement_names('requirements-tools.txt')
    assert {'matplotlib', 'tqdm', 'pyulog', 'pymavlink', 'h5py', 'distributed'} <= tools and not tools & robot
    for name in _imported_top_level() - used:
        assert _PIP.get(name, name).lower() in tools or _ROSDEP.get(name, name) in _exec_depends(), name


def test_pip_extras_are_the_requirements_files():
    """`pip install .[robot]` / `.[tools]` install what the two requirements files name (setup.py reads them)."""
    from importlib.metadata import metadata
    md = metadata('gyro_thermal_comp')
    assert {'robot', 'tools'} <= set(md.get_all('Provides-Extra'))

    def extra(name):
        return {re.split(r'[<>=;\[ ]', r)[0].lower() for r in md.get_all('Requires-Dist') if f'extra == "{name}"' in r}
    robot = _requirement_names('requirements-robot.txt')
    assert extra('robot') == robot
    assert extra('tools') == robot | _requirement_names('requirements-tools.txt')


def test_license_file_is_the_declared_apache_2():
    text = (REPO / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
    assert ET.parse(REPO / 'package.xml').getroot().findtext('license') == 'Apache-2.0'
    assert "license='Apache-2.0'" in (REPO / 'setup.py').read_text()


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(REPO / 'setup.cfg')
    assert cfg['develop']['script_dir'] == '$base/lib/gyro_thermal_comp'
    assert cfg['install']['install_scripts'] == '$base/lib/gyro_thermal_comp'
    assert (REPO / 'resource' / 'gyro_thermal_comp').is_file()


def test_venv_is_ignored_by_git():
    assert '.venv/' in (REPO / '.gitignore').read_text().split()


def test_readme_parameter_table_matches_the_code():
    """The robot-wiring table's defaults are the node's (a renamed or re-defaulted parameter fails),
    and it lists the parameters config/stkf.yaml opens with, no more, no fewer."""
    from gyro_thermal_comp.nodes.parameters import STKF_FILE_SECTIONS, all_specs
    specs = {s.name: s for s in all_specs()}
    section = (REPO / 'README.md').read_text().split('## Wiring it into a robot')[1].split('\n## ')[0]
    rows = re.findall(r'^\| `([\w.]+)` \| (`[^`]*`|unset) \|', section, flags=re.MULTILINE)
    assert len(rows) >= 8
    assert [name for name, _ in rows] == list(STKF_FILE_SECTIONS[0][1])
    for name, default in rows:
        assert name in specs, f'README names a parameter the node does not have: {name}'
        expected = specs[name].default
        if default == 'unset':
            assert expected is None or expected != expected, name   # None or NaN: unset
        else:
            assert ast.literal_eval(default.strip('`')) == expected, f'{name}: README {default}, code {expected!r}'
