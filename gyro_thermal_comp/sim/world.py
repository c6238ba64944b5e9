"""What a scenario is made of: the `World` it builds from its params (body motion, sensor mount,
temperature profile, Earth) and the `Scenario` record, with the pieces several scenario modules
share. scenarios.py holds the registry; the scenario modules import from here, never from it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .earth import earth_rate_enu, geomagnetic_field_enu
from .thermal import TemperatureProfile, warm_up_shape


@dataclass(frozen=True)
class World:
    motion: object            # .state(t) -> BodyState
    mount: object             # .state(t, body) -> MountState; .has_joint
    profile: TemperatureProfile
    earth_rate_enu: np.ndarray
    field_enu: np.ndarray
    aux_mount: object = None  # auxiliary IMU's mount (carousel_flip), None: no imu_aux stream


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    duration_s: float
    preset: str
    build: Callable[[dict], World]
    effects: dict
    params: dict
    episodes: tuple = ()          # (kind, start_s, duration_s, size)
    rates: tuple = (100.0, 50.0, 10.0, 100.0)   # imu, mag, temp, truth, Hz
    optional_params: dict = field(default_factory=dict)   # accepted, absent from cfg.params unless set
    aux_preset: str | None = None                        # auxiliary IMU preset (imu_aux stream)
    episode_labels: tuple = ()    # per episode: the profile phase it sits on (cfg.outage_labels)
    # second truth family (family_b.py): draws profile, shapes and outages at make_config; build(p, truth)
    draw_truth: Callable | None = None


def earth_vectors(p) -> tuple[np.ndarray, np.ndarray]:
    """(Earth rate, geomagnetic field), ENU, at the params' latitude, field strength, dip and declination."""
    return (earth_rate_enu(np.deg2rad(p['latitude_deg'])),
            geomagnetic_field_enu(p['field_ut'] * 1e-6, np.deg2rad(p['dip_deg']),
                                  np.deg2rad(p['declination_deg'])))


def tilt_gains(p) -> dict:
    """A vehicle body's roll and pitch per unit of lateral and longitudinal acceleration, rad/(m/s^2)."""
    return dict(roll_gain=np.deg2rad(p['roll_gain_deg_per_mps2']), pitch_gain=np.deg2rad(p['pitch_gain_deg_per_mps2']))


def warm_up_profile(p) -> TemperatureProfile:
    """A unit warming from temp_start_c towards temp_peak_c after still_s, time constant warmup_tau_s."""
    return TemperatureProfile(warm_up_shape(p['still_s'], p['warmup_tau_s'], 1e5), p['temp_start_c'], p['temp_peak_c'])
