"""Shared test set-up: DDS stays on loopback, on a domain of our own; paths to the bundled bags."""
import os
import sys
from pathlib import Path

import pytest

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# Our own domain per test session (0..101 are safe on Linux), so parallel runs do not cross-talk.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('GTC_TEST_DOMAIN_ID', str(50 + os.getpid() % 50))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('MPLBACKEND', 'Agg')

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'


def bundled_bags() -> list[Path]:
    return sorted(p for p in BAGS.iterdir() if (p / 'metadata.yaml').is_file())


@pytest.fixture(scope='session')
def repo() -> Path:
    return REPO
