"""`colcon build` the package and check the install layout `ros2 run` relies on.

ros2run resolves `ros2 run PKG EXE` through ament_index: the package's prefix from the
`packages` resource, then PREFIX/lib/PKG/EXE. We build with real colcon (colcon-core + colcon-ros
from PyPI) into a temporary workspace and resolve the executables the same way.
"""
import os
import subprocess
import sys
from pathlib import Path

from conftest import PKG, REPO
EXECUTABLES = ['gyro-thermal-comp', 'stkf_node', 'carousel_node']


def test_ament_index_marker_and_share_files(colcon_install):
    share = colcon_install / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PKG).is_file()
    assert (share / PKG / 'package.xml').is_file()
    config = sorted(p.name for p in (share / PKG / 'config').glob('*.yaml'))
    assert config == sorted(p.name for p in (REPO / 'config').glob('*.yaml')) and config
    launch = sorted(p.name for p in (share / PKG / 'launch').glob('*.launch.py'))
    assert launch == sorted(p.name for p in (REPO / 'launch').glob('*.launch.py')) and launch


def test_executables_resolve_like_ros2_run(colcon_install, monkeypatch):
    from ament_index_python.packages import get_package_prefix
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(colcon_install))
    prefix = Path(get_package_prefix(PKG))
    assert prefix == colcon_install
    for exe in EXECUTABLES:
        path = prefix / 'lib' / PKG / exe   # what ros2run's get_executable_path looks for
        assert path.is_file() and os.access(path, os.X_OK), f'{path} missing or not executable'


def test_installed_cli_runs(colcon_install):
    site = next(colcon_install.glob('lib/python3*/site-packages'))
    env = dict(os.environ, PYTHONPATH=f'{site}{os.pathsep}{os.environ.get("PYTHONPATH", "")}')
    proc = subprocess.run([sys.executable, str(colcon_install / 'lib' / PKG / 'gyro-thermal-comp'),
                           'simulate', '--list'], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert 'static_ramp' in proc.stdout
    # It ran the installed copy, not the source tree.
    proc = subprocess.run([sys.executable, '-c', 'import gyro_thermal_comp; print(gyro_thermal_comp.__file__)'],
                          env=env, capture_output=True, text=True, cwd=colcon_install)
    assert str(site) in proc.stdout
