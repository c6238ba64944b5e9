"""Shared test set-up: DDS stays on loopback, on a domain of our own; paths to the bundled bags."""
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# Our own domain per test session (0..101 are safe on Linux), so parallel runs do not cross-talk;
# pytest-xdist's two workers (`make test`) take one of an even/odd pair each, never the same one.
_WORKER = int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0')[2:] or 0) % 2
os.environ['ROS_DOMAIN_ID'] = os.environ.get('GTC_TEST_DOMAIN_ID', str(50 + (os.getpid() % 25) * 2 + _WORKER))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('MPLBACKEND', 'Agg')

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'



def random_batches(chunks, seed: int, n: int) -> list:
    """The chunks cut at n random times 3 ms - 1 s apart, stream by stream: a live node's batches."""
    from gyro_thermal_comp.carousel.synthetic import split_chunk
    edges = np.cumsum(np.random.default_rng(seed).uniform(0.003, 1.0, n))
    return [p for c in chunks for p in split_chunk(c, edges[(edges > c.imu.t[0]) & (edges < c.imu.t[-1])])]


def assert_same_records(a, b, modes: bool = True) -> None:
    """Two runs' demodulated records agree: stamps to 1e-9 s, body rates and specific forces to 1e-12
    (and mode and reason, with `modes`). The caller asserts how many there are."""
    for x, y in zip(a, b):
        if modes:
            assert (x.mode, x.reason) == (y.mode, y.reason)
        assert x.t_s == pytest.approx(y.t_s, abs=1e-9)
        np.testing.assert_allclose(x.rate_body_rad_s, y.rate_body_rad_s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(x.specific_force_body_m_s2, y.specific_force_body_m_s2, rtol=0, atol=1e-12)

def bundled_bags() -> list[Path]:
    return sorted(p for p in BAGS.iterdir() if (p / 'metadata.yaml').is_file())


@pytest.fixture(scope='session')
def repo() -> Path:
    return REPO


PKG = 'gyro_thermal_comp'


@pytest.fixture(scope='session')
def colcon_install(tmp_path_factory) -> Path:
    """The package built with real colcon into a temporary workspace: install/gyro_thermal_comp."""
    colcon = Path(sys.executable).with_name('colcon')
    if not colcon.exists():
        pytest.fail('colcon is not installed in this environment (requirements-test.txt)')
    ws = tmp_path_factory.mktemp('ws')
    shutil.copytree(REPO, ws / 'src' / PKG, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'bags', 'build', 'install', 'log', '__pycache__', '*.egg-info', '.pytest_cache'))
    env = dict(os.environ, PATH=f'{Path(sys.executable).parent}{os.pathsep}{os.environ["PATH"]}')
    proc = subprocess.run([str(colcon), 'build', '--base-paths', 'src', '--build-base', 'build',
                           '--install-base', 'install', '--event-handlers', 'console_direct-'],
                          cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return ws / 'install' / PKG


def installed_env(install: Path) -> dict:
    """Environment in which the colcon-installed copy (not the source tree) is imported."""
    site = next(install.glob('lib/python3*/site-packages'))
    return dict(os.environ, PYTHONPATH=f'{site}{os.pathsep}{os.environ.get("PYTHONPATH", "")}',
                AMENT_PREFIX_PATH=f'{install}{os.pathsep}{os.environ.get("AMENT_PREFIX_PATH", "")}')


class Freezer:
    """Freezes this process's child running `module` (SIGSTOP, then SIGCONT) `count` times for
    `freeze_s`, the first after `first_after_s`: what a loaded CPU does to a node, made repeatable.
    Use as a context manager around a live replay; `frozen` counts the freezes that happened."""

    def __init__(self, module: str, first_after_s: float = 4.0, count: int = 3, freeze_s: float = 3.0,
                 every_s: float = 6.0):
        self.module, self.first_after_s, self.count = module, first_after_s, count
        self.freeze_s, self.every_s = freeze_s, every_s
        self.frozen = 0
        self._stop = threading.Event()

    def _child(self) -> int | None:
        out = subprocess.run(['pgrep', '-P', str(os.getpid()), '-f', self.module], capture_output=True, text=True)
        pids = out.stdout.split()
        return int(pids[0]) if pids else None

    def _run(self) -> None:
        if self._stop.wait(self.first_after_s):
            return
        for _ in range(self.count):
            pid = self._child()
            if pid is not None:
                try:
                    os.kill(pid, signal.SIGSTOP)
                    self.frozen += 1
                    self._stop.wait(self.freeze_s)
                finally:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(pid, signal.SIGCONT)
            if self._stop.wait(self.every_s):
                return

    def __enter__(self) -> 'Freezer':
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


@pytest.fixture
def ros():
    """rclpy initialised for one test (imported here: the environment above is set first)."""
    import rclpy
    rclpy.init()
    yield
    rclpy.try_shutdown()


class Capture:
    """Stands in for a publisher: keeps what the node publishes."""

    def __init__(self):
        self.msgs = []

    def publish(self, msg):
        self.msgs.append(msg)
