"""Sensor simulator: raw IMU, magnetometer, temperature and truth streams as SensorChunks.

    cfg = make_config('static_ramp', seed=3, effects={'thermal_lag': 0})
    for chunk in simulate(cfg): ...
    cfg = make_family_config('B', 'outages', seed=3)   # the second truth family: report only

Models, magnitudes and sources: docs/simulator.md. No ROS imports here.
"""
from .config import SimConfig, make_config
from .effects import EFFECTS, EffectSpec
from .engine import CHUNK_S, EPOCH_NS, simulate
from .scenarios import SCENARIOS
from .sensors import covariances
from .truth_family import FamilyCase, family_configs, make_family_config

__all__ = ['CHUNK_S', 'EFFECTS', 'EPOCH_NS', 'EffectSpec', 'FamilyCase', 'SCENARIOS', 'SimConfig', 'covariances',
           'family_configs', 'make_config', 'make_family_config', 'simulate']
