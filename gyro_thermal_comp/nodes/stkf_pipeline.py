"""`StkfPipeline`: what the STKF node computes, from decoded input samples to the numbers it
publishes (no ROS here: stkf_node.py decodes messages, pushes them here, and encodes and publishes
what comes out).

Two paths (thermal/compensator.py). Each sample of every topic first meets its stream's one guard
in the `ThermalCompensator` (thermal/inputs.py). An IMU sample comes out at once (`push_imu` returns
it) from the estimator's state at its latest row at or before the stamp minus `output_delay_s`.
Every kept sample also goes to the `StampMerger` (stamp_merger.py), which releases them in stamp
order; `poll` runs the estimator on what it releases (the slow path) and returns the IMU samples
that had to wait for it, now compensated. Offline, `push_chunk` does both for a chunk already in
stamp order. Which state compensates a sample depends on stamps only, so a live node and an offline
run over the same bag give the same numbers.

The outputs carry REP 145 covariances: the rates' from the noise model and the drift's sigma, the
orientation's from `OrientationVariance` (orientation_uncertainty.py), whose roll and pitch
variances are held from the anchor row like roll and pitch themselves. The pipeline is not
thread-safe: a node calls it under one lock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import topics
from ..learning_status import LearningStatus, learning_line
from ..samples import SensorChunk
from ..stamps import TimeOrigin, ns_at
from ..thermal.compensator import QUEUED, ThermalCompensator
from ..thermal.estimator import EstimatorConfig, ThermalOutput, reason_names
from ..thermal.fast_path import FastOutput
from .node_health import MOTION_REASONS
from .orientation_uncertainty import OrientationVariance
from .stamp_merger import StampMerger, chunk_from_released, poll_gap_s
from .stkf_outputs import OneOutput, OutputArrays
from .world_frame import world_quat, world_quat_one


@dataclass(frozen=True)
class PipelineDiagnostics:
    """The pipeline's part of a node's diagnostics, in the order the node lists its key values:
    `values` first (the numbers a robot team reads, the drift model's parameters and sigmas, the
    core's counters under `core.`), the node's input and output counters, then `outputs`, then
    `status`. `health`: the fields of node_health.NodeHealth the pipeline knows."""
    values: dict
    outputs: dict
    status: dict
    health: dict


class StkfPipeline:
    """`cfg`: the estimator's configuration; `values`: the node's parameter values (parameters.py;
    the stamp merger's bounds, output_delay_s, the orientation floors, world_frame, the
    accelerometer's noise density); `streams`: the input streams, in the stamp merger's order."""

    def __init__(self, cfg: EstimatorConfig, values: dict, streams):
        self.compensator = ThermalCompensator(cfg, values['output_delay_s'], held=self._held_variances)
        self.estimator = self.compensator.estimator
        self.merger = StampMerger(streams, max_latency_s=values['max_latency_s'],
                                  max_buffered=values['buffer_max_samples'],
                                  max_poll_gap_s=poll_gap_s(values['process_period_s']),
                                  first_sample_wait_s=values['first_sample_wait_s'])
        self.orientation_variance = OrientationVariance.from_params(values, cfg)
        self.world_frame = values['world_frame']
        self.accel_noise_density = values['accel_noise_density_m_s2_rthz']
        self.time_origin = TimeOrigin()   # the core runs on s since the first stamp (replay sets it)
        self.imu_frame: str | None = None   # frame_id of the first IMU sample
        self.build_heading = True         # `push_imu`'s output carries q_heading
        self._imu_period_s: float | None = None
        self._last_out: dict | None = None   # the estimator's latest row, for the diagnostics
        self._drift_var = 0.0   # (rad/s)^2, variance of the drift estimate, for the rates' covariance
        self.learning_status = LearningStatus(cfg.window_s)   # why nothing is learned, if it is not

    # ------------------------------------------------------------------ input
    def push_imu(self, ns: int, frame_id: str, header: bytes, row) -> tuple[bool, OneOutput | OutputArrays | None]:
        """One IMU sample as it arrives (stamp ns, its header as CDR, row = [gx, gy, gz rad/s, ax, ay,
        az m/s^2]): whether the estimator takes it (False: its guard dropped it, or it came after its
        time was released), and what is ready to publish now: this sample, or the queued ones before
        it (and maybe it)."""
        if self.imu_frame is None:
            self.imu_frame = frame_id
        self.merger.arrived('imu')
        kept, out = self.compensator.push(ns, row[:3], row[3:], carry=(header, row[3:]))
        accepted = kept and self.merger.push('imu', self.time_origin.seconds(ns), row)
        if out is QUEUED:   # it waits for the estimator, or behind samples that do
            return accepted, self._take_ready()
        return accepted, (None if out is None else self._one(header, row[3:], out))

    def push_mag(self, ns: int, row) -> bool:
        """One compass sample (row = [bx, by, bz] T): past its guard into the stamp merger; False if
        it is dropped."""
        return self._push('mag', ns, row)

    def push_temperature(self, ns: int, row) -> bool:
        """One temperature sample (row = [degC]): past its guard into the stamp merger; False if it
        is dropped."""
        return self._push('temperature', ns, row)

    def _push(self, stream: str, ns: int, row) -> bool:
        self.merger.arrived(stream)
        return self.compensator.admit(stream, ns, row) and self.merger.push(stream, self.time_origin.seconds(ns), row)

    def malformed(self, stream: str) -> None:
        """Count a message of `stream` that could not be read at all."""
        self.merger.malformed(stream)

    def poll(self, flush: bool = False, unpublished=()) -> OutputArrays | None:
        """Run the estimator on what the stamp merger releases (everything with `flush`, after which
        nothing more reaches the estimator) and return the queued samples now ready to publish.
        `unpublished`: streams nothing publishes now (they hold nobody back)."""
        ready = self.merger.pop_ready(flush=flush, unpublished=unpublished)
        chunk = chunk_from_released(ready) if ready else None
        if chunk is not None and chunk.imu is not None:
            self._estimate(chunk)
        if flush:
            self.compensator.finish()
        return self._take_ready()

    def push_chunk(self, chunk: SensorChunk) -> OutputArrays | None:
        """Offline (replay): stamp-ordered samples with IMU samples in them, in one go: queue the IMU
        samples, run the estimator, return what is ready to publish."""
        self.imu_frame = self.imu_frame or topics.IMU_FRAME
        origin_ns = self.time_origin.ns or 0
        kept = self.compensator.add_many(ns_at(chunk.imu.t, origin_ns), chunk.imu.gyro, chunk.imu.accel,
                                         carry=(np.full(chunk.imu.t.size, None, object), chunk.imu.accel))
        self._estimate(self.compensator.admitted(chunk, origin_ns, kept))
        return self._take_ready()

    # ------------------------------------------------------------------ slow path: the estimator
    def _estimate(self, chunk: SensorChunk) -> None:
        out = self.compensator.estimate(chunk, self.time_origin.ns or 0)
        if len(out.track.t) > 1:
            self._imu_period_s = float(np.median(np.diff(out.track.t)))
        if len(out.track.t):
            self._last_out = {'reasons': int(out.reasons[-1]), 'gate_open': bool(out.gate_open[-1]),
                              'drift_rad_s': float(out.track.drift_rad_s[-1])}
            if np.isfinite(out.temperature_c[-1]):
                self._last_out['temperature_c'] = float(out.temperature_c[-1])
        self.learning_status.add(out.track.t, out.reasons, out.valid,
                                 self.estimator.counters().get('filter_updates', 0), self.estimator.drift_window_s)

    def _held_variances(self, out: ThermalOutput, chunk: SensorChunk) -> dict:
        return self.orientation_variance.held_tilt(out, chunk.imu.accel, self.estimator.tilt_max_rate_rad_s)

    # ------------------------------------------------------------------ output
    def _take_ready(self) -> OutputArrays | None:
        """The queued IMU samples whose anchor is final (thermal/fast_path.py), as published."""
        n, out, carried = self.compensator.take_ready()
        if not n:
            return None
        headers, accel = carried     # what push_imu / push_chunk queued with the samples
        return self._arrays(out, headers, accel)

    def _one(self, header: bytes, accel, out) -> OneOutput:
        """`_arrays` for one sample from `FastPath.run_one`, in Python floats (the live path)."""
        k, wx, wy, wz, yaw, heading_var = out
        held = self.compensator.anchor_held
        gyro_var, accel_var = self._noise_variances()
        frame = self.world_frame
        yaw_var = self.orientation_variance.yaw_variance(heading_var)
        q_imu = world_quat_one(float(held['roll'][k]), float(held['pitch'][k]), yaw, frame)
        return OneOutput(header, (wx, wy, wz), accel, q_imu,
                         (float(held['roll_var'][k]), float(held['pitch_var'][k]), yaw_var), gyro_var, accel_var,
                         world_quat_one(0.0, 0.0, yaw, frame) if self.build_heading else None)

    def _arrays(self, out: FastOutput, headers: np.ndarray, accel: np.ndarray) -> OutputArrays:
        """The published numbers of the samples out.ok marks (never NaN)."""
        ok = out.ok
        gyro_var, accel_var = self._noise_variances()
        h = out.held
        yaw = out.heading[ok]
        frame = self.world_frame
        zeros = np.zeros(yaw.size)
        return OutputArrays(
            ns=out.ns[ok], frame_id=self.imu_frame or topics.IMU_FRAME, headers=headers[ok],
            gyro=out.gyro_compensated[ok], accel=accel[ok], q_imu=world_quat(h['roll'][ok], h['pitch'][ok], yaw, frame),
            q_heading=world_quat(zeros, zeros, yaw, frame),   # the levelled IMU frame
            orientation_var=np.column_stack((h['roll_var'][ok], h['pitch_var'][ok],
                                             self.orientation_variance.yaw_variance(out.heading_var[ok]))),
            gyro_var=gyro_var, accel_var=accel_var)

    def _noise_variances(self) -> tuple[float, float]:
        """Rate and accelerometer variances for REP 145, from the noise model."""
        fs = 1.0 / self._imu_period_s if self._imu_period_s else 100.0
        arw = self.estimator.cfg.arw_rad_sqrt_s
        drift_var = self._drift_var  # refreshed with the diagnostics (1 Hz): too costly per sample
        return arw ** 2 * fs + drift_var, self.accel_noise_density ** 2 * fs

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self) -> PipelineDiagnostics:
        """Key values (node_health.py) with their units in their names: temperature (degC), drift and
        its sigma (deg/s), heading and yaw sigma (deg), time since the last compass correction (s);
        then the drift-model parameters (`param.<term> [unit]`, `sigma.<term> [unit]`) and the
        core's counters under `core.`. Refreshes the drift variance the rates' covariance carries."""
        est = self.estimator
        d = est.diagnostics()
        self._drift_var = float(np.nan_to_num(d.get('drift_sigma_rad_s', 0.0))) ** 2
        counters = est.counters()
        last = self._last_out or {}
        heading_sigma_deg = math.degrees(d['heading_sigma_rad'])
        age_s = d['temperature_age_s']
        values = {
            'temperature_c': last.get('temperature_c', 'none'),
            'temperature_age_s': age_s if math.isfinite(age_s) else 'no reading yet',
            'drift_deg_s': math.degrees(last['drift_rad_s']) if 'drift_rad_s' in last else 'none yet',
            'drift_sigma_deg_s': math.degrees(d['drift_sigma_rad_s']),
            'heading_sigma_deg': heading_sigma_deg,
            'yaw_sigma_deg': math.degrees(math.sqrt(float(
                self.orientation_variance.yaw_variance(d['heading_sigma_rad'] ** 2)))),
            'since_compass_update_s': d['coasting_for_s'],
            'gate_open': d['gate_open'],
            'gate_reasons': ','.join(d.get('gate_reasons', [])) or 'none',
            'filter_updates': counters.get('filter_updates', 0),
        }
        units = dict(zip(est.model.names, (t.unit for t in est.model.terms)))
        units['constant_at_0c'] = units.get('constant', 'rad/s')
        for name, value in d.get('params', {}).items():
            values[f'param.{name} [{units.get(name, "SI")}]'] = value
        for name, value in d.get('param_sigmas', {}).items():
            values[f'sigma.{name} [{units.get(name, "SI")}]'] = value
        for key in ('heading_sigma_rad', 'drift_sigma_rad_s', 'temperature_stuck', 'temperature_stuck_for_s',
                    'window_r_scale'):
            values[key] = d[key]
        values.update({f'core.{k}': v for k, v in counters.items()})
        outputs = {'outputs_not_published': self.compensator.not_published,   # the input guard's drops, NaN
                   'outputs_waited': self.compensator.waited}   # the estimator lagged more than output_delay_s
        status = {'still_period': est.still_use or 'running'}
        if 'reasons' in last:
            status['last_sample_reasons'] = ','.join(reason_names(last['reasons'])) or 'none'
        learn = est.cfg.learn
        health = dict(
            started=bool(d.get('started')), waiting=self._waiting_status(),
            gate_open=bool(d['gate_open']), gate_reasons=tuple(d.get('gate_reasons', [])),
            since_compass_s=float(d['coasting_for_s']), heading_sigma_deg=heading_sigma_deg,
            temperature_age_s=age_s, temperature_timeout_s=est.cfg.temperature_timeout_s,
            temperature_stuck=bool(d.get('temperature_stuck')), imu_for_s=est.imu_span_s,
            learn=learn, filter_updates=int(counters.get('filter_updates', 0)),
            not_learning=self.learning_status.verdict(counters) if learn else None,
            stalled=(self.learning_status.verdict(counters, since_update=True, by_design=MOTION_REASONS)
                     if learn else None))
        return PipelineDiagnostics(values, outputs, status, health)

    def _waiting_status(self) -> str:
        left = self.estimator.still_left_s
        if left is None:
            return 'waiting for the still period: no data yet'
        return f'waiting for the still period to end: {max(left, 0.0):.0f} s left (keep the unit motionless)'

    def learning_summary(self) -> str:
        """One line: the filter's updates so far, or why it made none (learning_status.py)."""
        return learning_line(self.learning_status, self.estimator.counters(), self.estimator.cfg.learn)
