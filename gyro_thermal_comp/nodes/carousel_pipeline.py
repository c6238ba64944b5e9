"""`CarouselPipeline`: what the carousel node computes, from decoded input samples to the numbers it
publishes (no ROS here: carousel_node.py decodes messages, pushes them here, and encodes and
publishes what comes out).

Each sample of every topic meets its stream's one guard in the `CarouselDemodulator` as it arrives
(`push`: carousel/buffers.InputGuards drops NaN, repeated or out-of-order stamps and counts them);
what it keeps goes to the `StampMerger` (stamp_merger.py), which releases the topics back in stamp
order. `poll` hands the demodulator what the merger releases, as admitted samples (not checked
again), and returns the records of the revolutions that closed. Offline, `push_chunk` gives the
demodulator a chunk already in stamp order, which it guards itself. The demodulator's output does
not depend on how its input is batched, so a live node and an offline run over the same bag publish
the same records.

Rate covariance (REP 145): every axis carries the gyro's white noise averaged over the interval
(`gyro_noise_density_rad_s_rthz`); the in-plane axes the variance of the lock-in bias estimate; the
spin axis is not modulated, so its gyro's zero-rate offset and its scale-factor error times the
spin rate stay in the output (`gyro_bias_sigma_rad_s`, `gyro_scale_factor_sigma`: datasheet
values); before the first lock-in estimate the in-plane axes carry the offset too. Not covered: a
vehicle's own rate changing within a wheel revolution (demodulation residual). The pipeline is not
thread-safe: a node calls it under one lock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..carousel import CarouselConfig, CarouselDemodulator
from ..carousel.records import DEMODULATED, DemodulatedOutput, RevolutionRecord
from ..samples import SensorChunk
from ..stamps import TimeOrigin
from .stamp_merger import StampMerger, chunk_from_released, poll_gap_s


@dataclass(frozen=True)
class CarouselOutput:
    """One record as published: the body-frame Imu's numbers (stamp `t_s`, s since the time origin;
    mean rate, rad/s, and specific force, m/s^2; the rates' variances, (rad/s)^2, body axes) and
    carousel/gyro_bias with its 1-sigma (imu_link x, y, z, rad/s; never NaN or inf)."""
    t_s: float
    rate_body_rad_s: np.ndarray
    specific_force_body_m_s2: np.ndarray
    rate_variances: np.ndarray
    gyro_bias_rad_s: tuple[float, float, float]
    gyro_bias_sigma_rad_s: tuple[float, float, float]


@dataclass(frozen=True)
class CarouselDiagnostics:
    """The pipeline's part of the node's diagnostics. `demodulating`: whole revolutions are being
    demodulated (OK), else pass-through (WARN), said by `message`. Key values in the order the node
    lists them: `state` (mode, reason), the node's published-record count, then `values` (the angle
    reference, the spin coupling and the demodulator's counters under `core.`), then the node's
    input and output counters."""
    demodulating: bool
    message: str
    state: dict
    values: dict


class CarouselPipeline:
    """`config`: the demodulator's configuration; `values`: the node's parameter values (parameters.py:
    the stamp merger's bounds, process_period_s, and the gyro's datasheet figures behind the rate
    variances); `streams`: the input streams, in the stamp merger's order."""

    def __init__(self, config: CarouselConfig, values: dict, streams):
        self.demodulator = CarouselDemodulator(config)
        self.merger = StampMerger(streams, max_latency_s=values['max_latency_s'],
                                  max_poll_gap_s=poll_gap_s(values['process_period_s']),
                                  first_sample_wait_s=values['first_sample_wait_s'])
        self.time_origin = TimeOrigin()   # the core runs on s since the first stamp (replay sets it)
        self.imu_frame: str | None = None   # frame_id of the first IMU sample (the node's hardware_id default)
        self._offset_sigma = values['gyro_bias_sigma_rad_s']   # rad/s, the offset nothing removes
        self._offset_var = self._offset_sigma ** 2
        self._noise_psd = values['gyro_noise_density_rad_s_rthz'] ** 2   # (rad/s)^2 / Hz
        self._scale_factor_sigma = values['gyro_scale_factor_sigma']
        # carousel axes -> body axes (the spin axis is carousel z): a diagonal covariance D maps to diag(M D M^T)
        self._axes_squared = np.square(np.asarray(config.carousel_to_body, dtype=float))

    # ------------------------------------------------------------------ input
    def push(self, stream: str, t: float, row, frame_id: str | None = None) -> bool:
        """One sample of `stream` (t: s since the time origin; its row layout, conversions.py) past its
        stream's guard into the stamp merger; False if it is dropped (the guard's counters, or the
        merger's when it came after its time was released). `frame_id`: the IMU's, kept from the first
        `imu` sample."""
        if stream == 'imu' and self.imu_frame is None and frame_id is not None:
            self.imu_frame = frame_id
        self.merger.arrived(stream)   # counted as received whether its guard keeps it or not
        return self.demodulator.admit(stream, t, row) and self.merger.push(stream, t, row)

    def poll(self, flush: bool = False, unpublished=()) -> DemodulatedOutput | None:
        """Demodulate what the stamp merger releases (everything with `flush`); None if it released
        nothing. `unpublished`: streams nothing publishes now (they hold nobody back)."""
        ready = self.merger.pop_ready(flush=flush, unpublished=unpublished)
        if not ready:
            return None
        return self.demodulator.update(chunk_from_released(ready), admitted=True)   # each passed `push`'s guard

    def push_chunk(self, chunk: SensorChunk) -> DemodulatedOutput:
        """Offline (replay): stamp-ordered samples in one go; the demodulator guards them itself."""
        return self.demodulator.update(chunk)

    def finish(self) -> DemodulatedOutput:
        """End of data: process what the demodulator still holds back (waiting for encoder or aux data,
        flip look-ahead) and close the last partial interval as a pass-through record."""
        return self.demodulator.flush()

    # ------------------------------------------------------------------ output
    def outputs(self, out: DemodulatedOutput | None) -> list[CarouselOutput]:
        """The records of `out` to publish, with their variances and bias estimates. A record with a
        non-finite rate or specific force is left out (never NaN on the wire; the demodulator counts it)."""
        if out is None:
            return []
        return [CarouselOutput(rec.t_s, rec.rate_body_rad_s, rec.specific_force_body_m_s2,
                               self._rate_variances(rec), *self._bias_estimates(rec))
                for rec in out.records
                if np.all(np.isfinite(rec.rate_body_rad_s)) and np.all(np.isfinite(rec.specific_force_body_m_s2))]

    def _rate_variances(self, rec: RevolutionRecord) -> np.ndarray:
        """Body-frame rate variances, (rad/s)^2: the gyro's white noise over the interval, plus in-plane
        the lock-in estimate's (the unremoved offset before there is one), on the spin axis its offset
        and scale-factor error times the spin rate."""
        noise_var = self._noise_psd / max(rec.duration_s, 1e-3)
        inplane = noise_var + (rec.gyro_bias_variance if math.isfinite(rec.gyro_bias_variance) else self._offset_var)
        spin = rec.spin_rate_rad_s if math.isfinite(rec.spin_rate_rad_s) else 0.0
        axial = noise_var + self._offset_var + (self._scale_factor_sigma * spin) ** 2
        return self._axes_squared @ np.array([inplane, inplane, axial])

    def _bias_estimates(self, rec: RevolutionRecord) -> tuple[tuple, tuple]:
        """((x, y, z) gyro bias estimates, (x, y, z) their 1-sigma), rad/s, imu_link: in-plane the lock-in's,
        axial the angle reference's learnt drift; an axis without an estimate 0 with the unremoved offset's
        sigma (`gyro_bias_sigma_rad_s`). Never NaN or inf."""
        offset = self._offset_sigma
        known = math.isfinite(rec.gyro_bias_variance)
        bx, by = (float(v) if math.isfinite(v) else 0.0 for v in rec.gyro_bias_inplane_rad_s)
        s_xy = math.sqrt(rec.gyro_bias_variance) if known else offset
        axial = math.isfinite(rec.axial_gyro_bias_variance) and math.isfinite(rec.axial_gyro_bias_rad_s)
        bz = float(rec.axial_gyro_bias_rad_s) if axial else 0.0
        s_z = math.sqrt(rec.axial_gyro_bias_variance) if axial else offset
        return (bx, by, bz), (s_xy, s_xy, s_z)

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self) -> CarouselDiagnostics:
        """The demodulator's mode and why (pass-through: the reason), where its angle comes from, the
        spin coupling's state and its counters (`core.`: drops by stream and cause, gaps, records and
        revolutions by kind)."""
        d = self.demodulator
        state = {'mode': d.mode, 'reason': d.reason or 'none'}
        values = {'angle_reference': d.angle_reference, 'spin_coupling': d.spin_coupling}
        values.update({f'core.{k}': v for k, v in d.counts.items()})
        if d.mode == DEMODULATED:
            return CarouselDiagnostics(True, 'demodulating whole revolutions', state, values)
        return CarouselDiagnostics(False, f'pass-through: {d.reason or "no rotation yet"}', state, values)
