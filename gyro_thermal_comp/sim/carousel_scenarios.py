"""Carousel scenarios for the encoder-free demodulator: a tilted (or level) body on a turntable
whose rate wobbles, steps to another rate, stops and restarts; a level one with magnetic interference
(the magnetometer as the angle reference, and its gate); and a wheel that accelerates, brakes, stops and
reverses (gravity less the rolling acceleration as the angle reference).

Registered into `scenarios.SCENARIO_DEFS` / `PARAM_SPECS` by scenarios.py (additive: no existing
scenario changes). The bag records the encoder too, so one record serves both angle sources.
"""
from __future__ import annotations

import numpy as np

from .motion import StaticPose, drive_and_reverse
from .mounts import AXLE_AXIS, VERTICAL_AXIS, JointMount, WheelJoint
from .world import Scenario, World, earth_vectors, tilt_gains, warm_up_profile

# name -> (min, max, meaning), merged into scenarios.PARAM_SPECS
PARAM_SPECS = {
    'wobble_pct': (0.0, 50.0, 'spin-rate wobble amplitude, % of the commanded rate'),
    'wobble_hz': (0.001, 50.0, 'spin-rate wobble frequency, Hz'),
    'spin_step_s': (0.0, 30 * 24 * 3600.0, 'the table ramps to spin_step_hz at this time, s'),
    'spin_step_hz': (0.0, 50.0, 'spin rate after spin_step_s, rev/s'),
    'spin_restart_s': (0.0, 30 * 24 * 3600.0, 'after spin_stop_s the table ramps back to its last rate here, s'),
    'reverse_speed_mps': (0.1, 60.0, 'backing-up speed, m/s'),
    'brake_s': (0.5, 600.0, 'braking from cruise to a stop takes this long, s'),
}


class ScheduledTurntable:
    """Rate levels reached by sin^2 ramps of spinup_s (each ramp starts at its time), plus a wobble
    wobble * level * sin(2 pi f t) on each level once its ramp is done. Angle in closed form."""

    def __init__(self, steps, spinup_s: float, wobble: float, wobble_hz: float):
        self.steps = [(float(t), 2 * np.pi * float(dhz)) for t, dhz in steps]   # (start s, rate change rad/s)
        self.spinup_s, self.wobble, self.w = float(spinup_s), float(wobble), 2 * np.pi * float(wobble_hz)

    def _ramp(self, t0: float, t):
        tau = np.maximum(t - t0, 0.0)
        tu = self.spinup_s
        up = tau < tu
        angle = np.where(up, 0.5 * tau - tu / (2 * np.pi) * np.sin(np.pi * np.minimum(tau, tu) / tu), 0.5 * tu + tau - tu)
        rate = np.where(up, np.sin(0.5 * np.pi * np.minimum(tau, tu) / tu) ** 2, 1.0)
        return angle, rate

    def angle_rate(self, t_s, body):
        t = np.asarray(t_s, dtype=float)
        angle, rate = np.zeros_like(t), np.zeros_like(t)
        for t0, d_omega in self.steps:
            a, r = self._ramp(t0, t)
            angle += d_omega * a
            rate += d_omega * r
            if self.wobble:        # the wobble of this level starts when its ramp ends
                t1 = t0 + self.spinup_s
                on = t > t1
                amp = self.wobble * d_omega
                rate += np.where(on, amp * np.sin(self.w * t), 0.0)
                angle += np.where(on, amp * (np.cos(self.w * t1) - np.cos(self.w * t)) / self.w, 0.0)
        return angle, rate


def _steps(p) -> list:
    """(start s, rate change rev/s) of the schedule: spin up, an optional step, stop and restart."""
    start, hz = p['still_s'], p['spin_hz']
    events = [(start, hz)]
    level = hz
    stop = p.get('spin_stop_s')
    step = p.get('spin_step_s')
    if step is not None and (stop is None or step < stop):
        events.append((max(step, start), p.get('spin_step_hz', hz) - level))
        level = p.get('spin_step_hz', hz)
    if stop is not None:
        stop = max(stop, start)           # spin_stop_s = 0 (static twin): never turns
        events.append((stop, -level))
        restart = p.get('spin_restart_s')
        if restart is not None and restart > stop and stop > start:
            events.append((restart, level))
    return events


def tilted_carousel(p):
    """Vertical turntable on a body at roll_deg/pitch_deg: gravity has an in-plane component
    g * sin(tilt) fixed in the body, which an encoder-free demodulator can take its angle from."""
    joint = ScheduledTurntable(_steps(p), p['spinup_s'], p.get('wobble_pct', 0.0) / 100.0, p.get('wobble_hz', 0.1))
    pose = StaticPose(np.deg2rad(p['roll_deg']), np.deg2rad(p['pitch_deg']), np.deg2rad(p['heading_deg']))
    return World(pose, JointMount(VERTICAL_AXIS, joint), warm_up_profile(p), *earth_vectors(p))


def wheel_drive(p):
    """MTi-1 at the hub of a wheel on the body's centre line (axle along body y), turning with the distance
    rolled: the simulator's accelerometer reads the body origin's specific force, so the hub sits there (a
    wheel off the centre line would also feel the yaw acceleration times its lateral offset)."""
    heading = np.deg2rad(p['heading_deg'])
    motion = drive_and_reverse(heading_rad=heading, still_s=p['still_s'], speed=p['speed_mps'],
                               reverse_speed=p['reverse_speed_mps'], brake_s=p['brake_s'], **tilt_gains(p))
    return World(motion, JointMount(AXLE_AXIS, WheelJoint(p['wheel_radius_m'], 0.0, heading)), warm_up_profile(p),
                 *earth_vectors(p))


def scenario_defs(common: dict, mti1_effects: dict) -> tuple:
    """The scenarios of this module (scenarios.py passes the params and the MTi-1 effects it shares)."""
    params = {**common, 'still_s': 60.0, 'spin_hz': 0.5, 'spinup_s': 5.0, 'encoder_counts': 4096.0,
              'temp_start_c': 25.0, 'temp_peak_c': 27.0, 'warmup_tau_s': 300.0, 'roll_deg': 2.0,
              'pitch_deg': -1.5, 'wobble_pct': 3.0, 'wobble_hz': 0.13}
    optional = {'spin_stop_s': None, 'spin_step_s': None, 'spin_step_hz': None, 'spin_restart_s': None}
    level = {**params, 'roll_deg': 0.0, 'pitch_deg': 0.0}
    return (Scenario(
        'carousel_tilted', 'MTi-1 on a vertical-axis turntable on a tilted body (roll_deg, pitch_deg; 0 for a level '
        'axis), 60 s still, spin_hz with a wobble_pct % wobble at wobble_hz; optional rate step (spin_step_s, '
        'spin_step_hz), stop (spin_stop_s) and restart (spin_restart_s). For encoder-free demodulation',
        300.0, 'mti1', tilted_carousel, mti1_effects, params, optional_params=optional),
        Scenario(
        'carousel_level_interference', 'carousel_tilted with a level axis (gravity gives no angle) and magnetic '
        'interference: a 15 uT field (steel nearby) from 120 to 180 s, 20 s fades. For the magnetometer as the '
        'encoder-free angle reference and its gate', 300.0, 'mti1', tilted_carousel, mti1_effects, level,
        episodes=(('strength', 120.0, 60.0, 15.0),), optional_params=optional),
        Scenario(
        'carousel_wheel_drive', 'MTi-1 at the hub of a wheel on the body centre line, sensor z along the axle; 60 s '
        'still, then laps of: pull away to speed_mps, cruise, a left turn, brake to a stop in brake_s, stand, back up '
        'at reverse_speed_mps, stop, stand. For the encoder-free wheel (gravity less the rolling acceleration)',
        300.0, 'mti1', wheel_drive, mti1_effects,
        {**common, 'still_s': 60.0, 'speed_mps': 6.0, 'reverse_speed_mps': 3.0, 'brake_s': 4.0, 'wheel_radius_m': 0.3,
         'roll_gain_deg_per_mps2': 0.4, 'pitch_gain_deg_per_mps2': 0.3, 'encoder_counts': 2048.0,
         'temp_start_c': 25.0, 'temp_peak_c': 30.0, 'warmup_tau_s': 300.0}))
