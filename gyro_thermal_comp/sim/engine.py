"""Chunked generation: simulate(cfg) streams SensorChunks of CHUNK_S seconds, carrying filter states.

Motion, temperature and interference are functions of time; only the stochastic and lagged parts
(die-temperature lag, hysteresis, rate random walk, Gauss-Markov bias, temperature-sensor lag) carry
state between chunks. Each noise source has its own random stream, so switching one effect never
changes another's draws. Stamps are k/rate from t = 0; truth stamps are every m-th IMU stamp.
Simulator time t is written to bags as the ROS stamp EPOCH_NS + t.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

import numpy as np
from scipy.signal import lfilter

from ..constants import STANDARD_GRAVITY_M_S2
from ..stamps import NS_PER_S
from ..samples import (ImuSamples, JointSamples, MagSamples, PoseSamples, SensorChunk, TemperatureSamples,
                       VectorSamples)
from .config import SimConfig
from .interference import interference_enu
from .scenarios import SCENARIO_DEFS
from .sensors import digitise, white_noise_std
from .thermal import T_REF_C, ThermalDrift
from .world import World

CHUNK_S = 60.0
# Simulator time 0 as a ROS stamp: 2024-01-01T00:00:00Z in ns since 1970 (a zero stamp makes drivers
# and imu_tools warn). A bag's first message is at t = 0, so its reader time (stamps.py) is simulator time.
EPOCH_NS = 1_704_067_200 * NS_PER_S
# random stream ids (each source its own stream of [seed, id]); 1: unit draw, 2: episodes (config.py)
_MAG_STREAM, _TEMP_STREAM = 3, 4
_IMU_STREAM_BASE, _IMU_AUX_STREAM_BASE = 10, 20   # + 0..3: gyro, accel, rate random walk, Gauss-Markov


def build_world(cfg: SimConfig) -> World:
    sc = SCENARIO_DEFS[cfg.scenario]
    return sc.build(cfg.params) if cfg.truth_family is None else sc.build(cfg.params, cfg.truth_family)


def sample_count(duration_s: float, rate_hz: float) -> int:
    """Number of stamps k/rate_hz < duration_s."""
    return max(0, math.ceil(duration_s * rate_hz - 1e-9))


def _index_range(j: int, rate_hz: float, n_total: int) -> tuple[int, int]:
    k0 = math.ceil(j * CHUNK_S * rate_hz - 1e-9)
    k1 = math.ceil((j + 1) * CHUNK_S * rate_hz - 1e-9)
    return min(k0, n_total), min(k1, n_total)


def _apply_t(rot, vec):
    """rot^T @ vec per sample (ENU or body -> sensor when rot maps sensor -> ENU or body)."""
    return np.einsum('nji,nj->ni', rot, vec)


class _Kinematics:
    """Body, mount and the sensor-frame quantities at N times."""

    def __init__(self, world: World, t: np.ndarray, mount=None):
        self.body = world.motion.state(t)
        self.mount = (mount or world.mount).state(t, self.body)
        self.rot_es = self.body.rot @ self.mount.rot_bs                 # sensor -> ENU
        self.rate_es = _apply_t(self.mount.rot_bs, self.body.rate_body) + self.mount.rate_bs_s
        self.force = _apply_t(self.mount.rot_bs, self.body.specific_force_body)

    def subset(self, sel) -> '_Kinematics':
        out = object.__new__(_Kinematics)
        out.body = type(self.body)(**{k: v[sel] for k, v in vars(self.body).items()})
        out.mount = type(self.mount)(**{k: (None if v is None else v[sel]) for k, v in vars(self.mount).items()})
        out.rot_es, out.rate_es, out.force = self.rot_es[sel], self.rate_es[sel], self.force[sel]
        return out


@dataclass(frozen=True)
class _ImuNoise:
    """The random streams of one IMU, one per noise source: [seed, stream_base + i] in field order."""
    gyro: np.random.Generator
    accel: np.random.Generator
    rate_random_walk: np.random.Generator
    gauss_markov: np.random.Generator

    @classmethod
    def streams(cls, seed: int, stream_base: int) -> '_ImuNoise':
        return cls(*(np.random.default_rng([seed, stream_base + i]) for i in range(4)))


class _ImuChannel:
    """One IMU (gyro + accel) on its mount: its unit, its own noise streams and carried states.

    The main IMU is one channel; an auxiliary IMU (imu_aux, the carousel's flip mechanism) is another
    with its own unit, preset, mount and stream_base.
    """

    def __init__(self, *, cfg: SimConfig, world: World, unit, preset, mount, stream_base: int,
                 gyro_noise_dps_rthz: float):
        rate, p = cfg.imu_rate_hz, cfg.params
        self.world, self.unit, self.preset, self.mount, self.rate_hz = world, unit, preset, mount, rate
        self.noise = _ImuNoise.streams(cfg.seed, stream_base)
        u = unit
        t_case0 = float(world.profile(np.array([-u.time_offset_s]))[0][0])
        if cfg.truth_family is not None and unit is cfg.unit:   # second family: its drift truth (main IMU)
            self.thermal = cfg.truth_family.drift(u, rate, t_case0)
        else:
            self.thermal = ThermalDrift(
                a_dps_per_c=u.gyro_a_dps_per_c, b_dps_per_c_per_s=u.gyro_b_dps_per_c_per_s, c_dps=u.gyro_c_dps,
                curvature_dps_per_c2=u.gyro_curvature_dps_per_c2, hysteresis_dps=u.gyro_hysteresis_dps,
                lag_s=u.thermal_lag_s, hysteresis_tau_s=p['hysteresis_tau_s'], rate_hz=rate, t_case0_c=t_case0)
        self.gyro_sigma = np.radians(white_noise_std(gyro_noise_dps_rthz, rate))
        self.accel_sigma = white_noise_std(preset.accel.noise_density_ug_rthz * 1e-6, rate) * STANDARD_GRAVITY_M_S2
        self.rrw_step = np.radians(u.gyro_rrw_dps_rts) / math.sqrt(rate)
        self.rrw = np.zeros(3)
        self.gm_phi = math.exp(-1.0 / (rate * p['bias_instability_tau_s']))
        gm_sigma = np.radians(u.gyro_bias_instability_dps)
        self.gm_gain = gm_sigma * math.sqrt(1.0 - self.gm_phi ** 2)
        self.gm_zi = (self.gm_phi * gm_sigma * self.noise.gauss_markov.standard_normal(3))[None, :]   # stationary start
        self.g_sensitivity = np.radians(u.gyro_g_sensitivity_dps_per_g) / STANDARD_GRAVITY_M_S2

    def sample(self, t: np.ndarray):
        """IMU samples stamped t -> (kinematics at t - time_offset, noise-free gyro rad/s, ImuSamples)."""
        u, world, n = self.unit, self.world, len(t)
        t_phys = t - u.time_offset_s
        kin = _Kinematics(world, t_phys, self.mount)
        earth_s = _apply_t(kin.rot_es, np.broadcast_to(world.earth_rate_enu, (n, 3)))
        w_is = kin.rate_es + earth_s                              # what an ideal gyro senses, rad/s
        drift, t_die = self.thermal.step(*world.profile(t_phys), t_phys)
        rrw = self.rrw + np.cumsum(self.rrw_step * self.noise.rate_random_walk.standard_normal((n, 3)), axis=0)
        if n:
            self.rrw = rrw[-1]
        gm, self.gm_zi = lfilter([1.0], [1.0, -self.gm_phi],
                                 self.gm_gain * self.noise.gauss_markov.standard_normal((n, 3)), axis=0, zi=self.gm_zi)
        sf = u.gyro_scale_factor + u.gyro_scale_factor_tc_per_c * (t_die - T_REF_C)[:, None]
        gyro_clean = (w_is * (1.0 + sf) + w_is @ u.gyro_cross_axis.T + kin.force @ self.g_sensitivity.T
                      + drift + rrw + gm)
        gyro_spec, accel_spec = self.preset.gyro, self.preset.accel
        gyro = digitise(gyro_clean + self.gyro_sigma * self.noise.gyro.standard_normal((n, 3)),
                        np.radians(gyro_spec.lsb_dps), np.radians(gyro_spec.range_dps))
        accel = digitise(kin.force + u.accel_bias_m_s2 + self.accel_sigma * self.noise.accel.standard_normal((n, 3)),
                         accel_spec.lsb_g * STANDARD_GRAVITY_M_S2, accel_spec.range_g * STANDARD_GRAVITY_M_S2)
        return kin, gyro_clean, ImuSamples(t, gyro, accel)


class _Run:
    def __init__(self, cfg: SimConfig):
        self.cfg, self.world = cfg, build_world(cfg)
        p = cfg.params
        self.mag_rng = np.random.default_rng([cfg.seed, _MAG_STREAM])
        self.temp_rng = np.random.default_rng([cfg.seed, _TEMP_STREAM])
        self.n_imu = sample_count(cfg.duration_s, cfg.imu_rate_hz)
        self.n_mag = sample_count(cfg.duration_s, cfg.mag_rate_hz)
        self.n_temp = sample_count(cfg.duration_s, cfg.temp_rate_hz)
        self.stride = round(cfg.imu_rate_hz / cfg.truth_rate_hz)
        self.n_chunks = max(1, math.ceil(cfg.duration_s / CHUNK_S))
        self.imu = _ImuChannel(cfg=cfg, world=self.world, unit=cfg.unit, preset=cfg.preset, mount=self.world.mount,
                               stream_base=_IMU_STREAM_BASE, gyro_noise_dps_rthz=p['gyro_noise_dps_rthz'])
        self.aux = None
        if self.world.aux_mount is not None:
            self.aux = _ImuChannel(cfg=cfg, world=self.world, unit=cfg.aux_unit, preset=cfg.aux_preset,
                                   mount=self.world.aux_mount, stream_base=_IMU_AUX_STREAM_BASE,
                                   gyro_noise_dps_rthz=cfg.aux_preset.gyro.noise_density_dps_rthz)
        lag = p['temp_lag_s']
        self.temp_alpha = math.exp(-1.0 / (cfg.temp_rate_hz * lag)) if lag > 0 else 0.0
        self.temp_zi = np.array([self.temp_alpha * float(self.world.profile(np.array([0.0]))[0][0])])
        self.encoder_step = 2 * np.pi / p['encoder_counts'] if 'encoder_counts' in p else None

    # -- streams ---------------------------------------------------------------------------------
    def _truth(self, t, k, kin_phys, gyro_clean):
        sel = (k % self.stride) == 0
        ts = t[sel]
        kin = kin_phys.subset(sel) if self.cfg.unit.time_offset_s == 0.0 else _Kinematics(self.world, ts)
        body = kin.body
        odom = PoseSamples(ts, body.quat, body.position, body.velocity_body, body.rate_body)
        bias = VectorSamples(ts, gyro_clean[sel] - kin.rate_es)
        dist = _apply_t(kin.rot_es, interference_enu(self.cfg.episodes, ts, self.world.field_enu))
        return odom, bias, VectorSamples(ts, dist)

    def _encoder(self, t, kin_phys) -> JointSamples | None:
        """The encoder is a sensor sampled with the IMU (not truth): every IMU stamp, true time."""
        if not self.world.mount.has_joint:
            return None
        kin = kin_phys if self.cfg.unit.time_offset_s == 0.0 else _Kinematics(self.world, t)
        step = self.encoder_step
        return JointSamples(t, step * np.round(kin.mount.joint_angle / step), kin.mount.joint_rate)

    def _mag(self, k0: int, k1: int) -> MagSamples:
        cfg, u, world, spec = self.cfg, self.cfg.unit, self.world, self.cfg.preset.mag
        t = np.arange(k0, k1) / cfg.mag_rate_hz
        kin = _Kinematics(world, t)
        field_e = world.field_enu + interference_enu(cfg.episodes, t, world.field_enu)
        b_ut = _apply_t(kin.rot_es, field_e) * 1e6
        gain = 1.0 + spec.sensitivity_tc_per_c * (world.profile(t)[0] - T_REF_C)
        sensed = gain[:, None] * (b_ut @ u.mag_soft_iron.T + u.mag_hard_iron_ut)
        noisy = sensed + spec.noise_ut * self.mag_rng.standard_normal((len(t), 3))
        return MagSamples(t, 1e-6 * digitise(noisy, spec.lsb_ut, spec.range_ut))

    def _temperature(self, k0: int, k1: int) -> TemperatureSamples:
        cfg, spec = self.cfg, self.cfg.preset.temp
        t = np.arange(k0, k1) / cfg.temp_rate_hz
        t_case = self.world.profile(t)[0]
        if self.temp_alpha > 0:
            a = self.temp_alpha
            t_case, self.temp_zi = lfilter([1.0 - a], [1.0, -a], t_case, zi=self.temp_zi)
        noisy = t_case + cfg.params['temp_noise_c'] * self.temp_rng.standard_normal(len(t))
        return TemperatureSamples(t, digitise(noisy, spec.lsb_c, 1000.0))

    def chunk(self, j: int) -> SensorChunk:
        cfg = self.cfg
        k = np.arange(*_index_range(j, cfg.imu_rate_hz, self.n_imu))
        t = k / cfg.imu_rate_hz
        kin, gyro_clean, imu = self.imu.sample(t)
        odom, bias, dist = self._truth(t, k, kin, gyro_clean)
        joint = self._encoder(t, kin)
        imu_aux = None if self.aux is None else self.aux.sample(t)[2]   # sampled with the main IMU
        return SensorChunk(imu=imu, mag=self._mag(*_index_range(j, cfg.mag_rate_hz, self.n_mag)),
                           temperature=self._temperature(*_index_range(j, cfg.temp_rate_hz, self.n_temp)),
                           odom=odom, gyro_bias=bias, mag_disturbance=dist, joint=joint, imu_aux=imu_aux)


def simulate(cfg: SimConfig) -> Iterator[SensorChunk]:
    """Stream the run as time-ordered SensorChunks of CHUNK_S s (the last may be shorter).

    Deterministic: the same cfg gives bit-identical arrays. Memory is bounded by one chunk.
    """
    if not isinstance(cfg, SimConfig):
        raise ValueError(f'simulate() needs a SimConfig from make_config(), got {type(cfg).__name__}')
    run = _Run(cfg)
    for j in range(run.n_chunks):
        chunk = run.chunk(j)
        if j == 0 or any(len(s.t) for s in chunk.streams().values()):   # a float-edge last chunk may be empty
            yield chunk
