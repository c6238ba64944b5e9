"""The README's two commands, .ci/run and the ament_python layout agree with each other."""
import ast
import configparser
import re
import sys
import xml.etree.ElementTree as ET

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


def _imported_top_level() -> set[str]:
    names = set()
    for path in (REPO / 'gyro_thermal_comp').rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split('.')[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - {'gyro_thermal_comp'}


# import name -> rosdep key, where they differ
_ROSDEP = {'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
           'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm'}


def test_every_imported_package_is_declared_for_rosdep_or_pip():
    """A workspace on an apt-installed Jazzy gets each import from package.xml (rosdep) or from
    requirements-robot.txt (pip, no rosdep key), never from neither."""
    deps = {e.text for e in ET.parse(REPO / 'package.xml').getroot().findall('exec_depend')}
    pip = {re.split(r'[<>=\[ ]', ln)[0].strip().lower()
           for ln in (REPO / 'requirements-robot.txt').read_text().splitlines() if ln.strip() and ln[0] != '#'}
    missing = sorted(name for name in _imported_top_level()
                     if _ROSDEP.get(name, name) not in deps and name.lower() not in pip)
    assert not missing, f'imported but neither in package.xml nor requirements-robot.txt: {missing}'
    assert not any(p.startswith('ros-') or p in ('numpy', 'rclpy') for p in pip), 'would shadow the system ROS'


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(REPO / 'setup.cfg')
    assert cfg['develop']['script_dir'] == '$base/lib/gyro_thermal_comp'
    assert cfg['install']['install_scripts'] == '$base/lib/gyro_thermal_comp'
    assert (REPO / 'resource' / 'gyro_thermal_comp').is_file()


def test_venv_is_ignored_by_git():
    assert '.venv/' in (REPO / '.gitignore').read_text().split()


def test_readme_parameter_table_matches_the_code():
    """The robot-wiring table's defaults are the node's (a renamed or re-defaulted parameter fails)."""
    from gyro_thermal_comp.nodes.parameters import all_specs
    specs = {s.name: s for s in all_specs()}
    section = (REPO / 'README.md').read_text().split('## Wiring it into a robot')[1].split('\n## ')[0]
    rows = re.findall(r'^\| `([\w.]+)` \| (`[^`]*`|unset) \|', section, flags=re.MULTILINE)
    assert len(rows) >= 8
    for name, default in rows:
        assert name in specs, f'README names a parameter the node does not have: {name}'
        expected = specs[name].default
        if default == 'unset':
            assert expected is None or expected != expected, name   # None or NaN: unset
        else:
            assert ast.literal_eval(default.strip('`')) == expected, f'{name}: README {default}, code {expected!r}'
