"""The README's two commands, .ci/run and the ament_python layout agree with each other."""
import configparser
import re
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


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(REPO / 'setup.cfg')
    assert cfg['develop']['script_dir'] == '$base/lib/gyro_thermal_comp'
    assert cfg['install']['install_scripts'] == '$base/lib/gyro_thermal_comp'
    assert (REPO / 'resource' / 'gyro_thermal_comp').is_file()


def test_venv_is_ignored_by_git():
    assert '.venv/' in (REPO / '.gitignore').read_text().split()
