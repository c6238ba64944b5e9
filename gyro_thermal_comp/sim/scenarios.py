"""The named scenarios: defaults (duration, rates, sensor, effects, params, interference) and the world
(body motion, sensor mount, temperature profile, Earth) each one builds from its params.

Every scenario starts motionless for at least 60 s (the estimator initialises c from that period).
"""
from __future__ import annotations

import numpy as np

from . import carousel_scenarios, family_b
from .effects import EFFECTS
from .motion import StaticPose, rectangle_laps, stop_and_go
from .mounts import (AXLE_AXIS, HORIZONTAL_AXIS, VERTICAL_AXIS, FixedMount, FlipJointMount, FlipSchedule, JointMount,
                     TurntableJoint, WheelJoint)
from .thermal import TemperatureProfile, static_ramp_shape
from .world import Scenario, World, earth_vectors, tilt_gains, warm_up_profile

# name -> (min, max, meaning). A scenario accepts the common params plus its own.
PARAM_SPECS: dict[str, tuple[float, float, str]] = {
    'latitude_deg': (-89.0, 89.0, 'geodetic latitude, deg (Earth rate projection)'),
    'declination_deg': (-180.0, 180.0, 'magnetic declination, deg east of true north'),
    'field_ut': (1.0, 100.0, 'geomagnetic total intensity, uT'),
    'dip_deg': (-89.0, 89.0, 'magnetic dip (inclination), deg, positive down'),
    'heading_deg': (-360.0, 360.0, 'initial yaw of the body, deg CCW from east'),
    'gyro_noise_dps_rthz': (0.0, 10.0, 'gyro white-noise density (ARW), deg/s/sqrt(Hz)'),
    'temp_lag_s': (0.0, 600.0, 'time constant of the temperature sensor itself, s'),
    'temp_noise_c': (0.0, 5.0, 'temperature sensor rms noise, degC'),
    'hysteresis_tau_s': (1.0, 1e5, 'relaxation time of the thermal hysteresis state, s'),
    'bias_instability_tau_s': (1.0, 1e5, 'correlation time of the Gauss-Markov bias, s'),
    'temp_start_c': (-40.0, 125.0, 'case temperature at the start, degC'),
    'temp_peak_c': (-40.0, 125.0, 'peak (or final) case temperature, degC'),
    'roll_deg': (-45.0, 45.0, 'static roll of the unit, deg'),
    'pitch_deg': (-45.0, 45.0, 'static pitch of the unit, deg'),
    'still_s': (0.0, 3600.0, 'motionless period at the start, s'),
    'warmup_tau_s': (1.0, 1e5, 'time constant of the temperature rise, s'),
    'speed_mps': (0.1, 60.0, 'cruise speed, m/s'),
    'turn_speed_mps': (0.1, 60.0, 'speed through turns, m/s'),
    'straight_s': (2.0, 3600.0, 'duration of a long side of the rectangle, s'),
    'short_straight_s': (2.0, 3600.0, 'duration of a short side of the rectangle, s'),
    'turn_s': (1.0, 600.0, 'duration of a 90 deg turn, s'),
    'roll_gain_deg_per_mps2': (0.0, 5.0, 'body roll per lateral acceleration, deg/(m/s^2)'),
    'pitch_gain_deg_per_mps2': (0.0, 5.0, 'body pitch per longitudinal acceleration, deg/(m/s^2)'),
    'spin_hz': (0.01, 50.0, 'carousel spin rate, rev/s'),
    'spinup_s': (0.1, 600.0, 'time to reach the spin rate, s'),
    'encoder_counts': (1.0, 2.0 ** 24, 'encoder counts per revolution (integer)'),
    'wheel_radius_m': (0.05, 2.0, 'wheel rolling radius, m'),
    'track_m': (0.0, 5.0, 'track width (wheel offset from the body centre line x2), m'),
    'spin_stop_s': (0.0, 30 * 24 * 3600.0, 'turntable starts braking (same ramp as spin-up) at this time, s'),
    'flip_period_s': (1.0, 3600.0, 'time between flips of the main IMU (alternately +90 and -90 deg), s'),
    'flip_s': (0.05, 10.0, 'duration of one 90 deg flip, s'),
}
# Params a scenario accepts but leaves out of cfg.params unless given, so that adding them changed no
# existing run (the bundled bags record cfg.params). Value: what the world uses when absent.
_TURNTABLE_OPTIONAL = {'spin_stop_s': None}

_COMMON = {'latitude_deg': 50.0, 'declination_deg': 7.0, 'field_ut': 50.0, 'dip_deg': 66.0,
           'heading_deg': 30.0, 'temp_lag_s': 2.0, 'temp_noise_c': 0.02, 'hysteresis_tau_s': 900.0,
           'bias_instability_tau_s': 300.0}

_RICH = {name: spec.default for name, spec in EFFECTS.items()}
_MTI1 = {'thermal_curvature': 2e-6, 'thermal_hysteresis': 2e-4, 'thermal_lag': 20.0, 'g_sensitivity': 0.003,
         'scale_factor': 0.001, 'scale_factor_thermal': 2e-5, 'cross_axis': 0.001, 'time_offset': 0.0,
         'compass_deviation': 0.5, 'rate_random_walk': 2e-5, 'bias_instability': 0.003}
_NONE = {name: 0.0 for name in EFFECTS}


def _static(p) -> World:
    return World(StaticPose(np.deg2rad(p['roll_deg']), np.deg2rad(p['pitch_deg']), np.deg2rad(p['heading_deg'])),
                 FixedMount(), TemperatureProfile(static_ramp_shape(), p['temp_start_c'], p['temp_peak_c']),
                 *earth_vectors(p))


def _vehicle(p) -> World:
    motion = rectangle_laps(heading_rad=np.deg2rad(p['heading_deg']), still_s=p['still_s'], speed=p['speed_mps'],
                            turn_speed=p['turn_speed_mps'], straight_s=p['straight_s'],
                            short_straight_s=p['short_straight_s'], turn_s=p['turn_s'], **tilt_gains(p))
    return World(motion, FixedMount(), warm_up_profile(p), *earth_vectors(p))


def _turntable(p) -> TurntableJoint:
    return TurntableJoint(p['spin_hz'], p['still_s'], p['spinup_s'], p.get('spin_stop_s'))


def _carousel(axis):
    def build(p) -> World:
        return World(StaticPose(0.0, 0.0, np.deg2rad(p['heading_deg'])), JointMount(axis, _turntable(p)),
                     warm_up_profile(p), *earth_vectors(p))
    return build


def _carousel_flip(p) -> World:
    """Vertical turntable; the main IMU flips about platform x every flip_period_s once spinning; the
    aux IMU sits on the platform unflipped (imu_aux frame = platform frame)."""
    joint = _turntable(p)
    stop = p.get('spin_stop_s')
    end = 1e9 if stop is None else stop - p['flip_period_s']   # no flips while braking or stopped
    schedule = FlipSchedule.alternating(p['still_s'] + p['spinup_s'] + p['flip_period_s'], p['flip_period_s'],
                                        p['flip_s'], end)
    return World(StaticPose(0.0, 0.0, np.deg2rad(p['heading_deg'])), FlipJointMount(VERTICAL_AXIS, joint, schedule),
                 warm_up_profile(p), *earth_vectors(p), aux_mount=JointMount(VERTICAL_AXIS, joint))


def _wheel(p) -> World:
    heading = np.deg2rad(p['heading_deg'])
    motion = stop_and_go(heading_rad=heading, still_s=p['still_s'], speed=p['speed_mps'],
                         turn_speed=p['turn_speed_mps'], **tilt_gains(p))
    joint = WheelJoint(p['wheel_radius_m'], p['track_m'], heading)
    return World(motion, JointMount(AXLE_AXIS, joint), warm_up_profile(p), *earth_vectors(p))


_STATIC_P = {**_COMMON, 'roll_deg': 0.6, 'pitch_deg': -0.9, 'temp_start_c': 23.0, 'temp_peak_c': 58.0}
_DRIVE_P = {'still_s': 60.0, 'roll_gain_deg_per_mps2': 0.4, 'pitch_gain_deg_per_mps2': 0.3,
            'warmup_tau_s': 700.0}
_CAROUSEL_P = {**_COMMON, 'still_s': 60.0, 'spin_hz': 0.5, 'spinup_s': 5.0, 'encoder_counts': 4096.0,
               'temp_start_c': 25.0, 'temp_peak_c': 27.0, 'warmup_tau_s': 300.0}

_DEFS = (
    Scenario('static_ramp', 'motionless ADXRS623 unit, 23 -> 58 -> ~24 degC at a non-uniform rate, 2 h, '
             'no interference (the paper\'s static test)', 7200.0, 'adxrs623', _static, _RICH, _STATIC_P),
    Scenario('static_ramp_outages', 'static_ramp plus magnetic interference of 300 s (heating ramp), 300 s (from '
             'the hold-to-cooling turn) and 600 s (cooling tail)', 7200.0, 'adxrs623', _static, _RICH, _STATIC_P,
             episodes=(('rotate', 1000.0, 300.0, 25.0), ('strength', 3300.0, 300.0, 12.0),
                       ('rotate', 5400.0, 600.0, 20.0)),
             episode_labels=('heating_ramp', 'hold_to_cooling_turn', 'cooling_tail')),
    Scenario('vehicle_loop', 'car with ADXRS623 unit: 60 s still, then counter-clockwise rectangle laps '
             '(152 s each), 26 -> 37 degC, vehicle compass deviation, three short interference episodes',
             1800.0, 'adxrs623', _vehicle, {**_RICH, 'compass_deviation': 3.0},
             {**_COMMON, **_DRIVE_P, 'speed_mps': 12.0, 'turn_speed_mps': 5.0, 'straight_s': 40.0,
              'short_straight_s': 20.0, 'turn_s': 8.0, 'temp_start_c': 26.0, 'temp_peak_c': 37.0},
             episodes=(('strength', 400.0, 20.0, 15.0), ('rotate', 950.0, 30.0, 20.0),
                       ('strength', 1500.0, 15.0, 10.0))),
    Scenario('carousel_vertical', 'MTi-1 on a turntable spinning about the vertical (sensor z up) at spin_hz '
             '(0.5 Hz; 4 Hz in the vehicle tests) after 60 s still, static base, 25 -> 27 degC', 300.0, 'mti1',
             _carousel(VERTICAL_AXIS), _MTI1, _CAROUSEL_P, optional_params=_TURNTABLE_OPTIONAL),
    Scenario('carousel_horizontal', 'as carousel_vertical with the spin axis horizontal along body x '
             '(sensor z forward)', 300.0, 'mti1', _carousel(HORIZONTAL_AXIS), _MTI1, _CAROUSEL_P,
             optional_params=_TURNTABLE_OPTIONAL),
    Scenario('carousel_flip', 'as carousel_vertical with the two-position mechanism: the MTi-1 flips 90 deg '
             'about platform x every flip_period_s (30 s) once spinning, alternately +1 and -1 quarter turn, '
             'in flip_s (0.5 s); an LSM9DS1-class auxiliary IMU on the platform (imu_aux) stands in',
             300.0, 'mti1', _carousel_flip, _MTI1, {**_CAROUSEL_P, 'flip_period_s': 30.0, 'flip_s': 0.5},
             optional_params=_TURNTABLE_OPTIONAL, aux_preset='lsm9ds1'),
    Scenario('carousel_wheel', 'MTi-1 at the hub of the right rear (non-steered) wheel, sensor z along the '
             'axle; 60 s still, then stop-and-go driving with turns; spin = wheel speed / radius', 300.0, 'mti1',
             _wheel, _MTI1, {**_COMMON, **_DRIVE_P, 'speed_mps': 8.0, 'turn_speed_mps': 4.0,
                             'wheel_radius_m': 0.3, 'track_m': 1.5, 'encoder_counts': 2048.0,
                             'temp_start_c': 25.0, 'temp_peak_c': 30.0, 'warmup_tau_s': 300.0}),
    Scenario('null', 'static_ramp with the paper\'s model exactly: drift = a*T + b*dT/dt + c (+ Earth rate), '
             'only white noise and quantisation; no lag of the temperature sensor', 7200.0, 'adxrs623',
             _static, _NONE, {**_STATIC_P, 'temp_lag_s': 0.0, 'temp_noise_c': 0.0}),
)

# The registry: the first family above, the encoder-free carousel scenarios and the second truth family
# (report only, names b_*); each module adds its own params.
PARAM_SPECS.update(carousel_scenarios.PARAM_SPECS)
PARAM_SPECS.update(family_b.PARAM_SPECS)
SCENARIO_DEFS: dict[str, Scenario] = {s.name: s for s in (*_DEFS, *carousel_scenarios.scenario_defs(_COMMON, _MTI1),
                                                          *family_b.scenario_defs(_COMMON, _RICH))}
SCENARIOS: dict[str, str] = {s.name: s.description for s in SCENARIO_DEFS.values()}

__all__ = ['PARAM_SPECS', 'SCENARIO_DEFS', 'SCENARIOS', 'Scenario', 'World']
