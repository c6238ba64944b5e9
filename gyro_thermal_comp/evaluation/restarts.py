"""The heading a node publishes after a restart, against the truth: a warm start from a saved state
at a chosen time of a record, in whatever state of motion the record is in there.

`saved_state` runs the estimator over a whole record (what a node's `state_file` holds after it);
`restart` starts the node's own code path (`ThermalCompensator` with the node's parameter values
and its published yaw variance, `nodes/orientation_uncertainty.py`) from that state at `start_s`
and returns, at the truth stamps of the next `span_s`, the published yaw's error and 1-sigma. How
often the 2-sigma covers the error is `covered`; `benchmarks/restart_coverage.py` writes the
figures, `test/test_restarts.py` checks them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..angles import euler_from_quat, wrap_angle
from ..bag_io import BagReader, read_chunks
from ..nodes.orientation_uncertainty import OrientationVariance
from ..nodes.parameters import all_specs, config_from_params
from ..samples import SensorChunk, slice_samples
from ..stamps import ns_at
from ..thermal.compensator import ThermalCompensator
from ..thermal.estimator import ThermalDriftEstimator

_INPUTS = ('imu', 'mag', 'temperature')


def node_values(**params) -> dict:
    """The STKF node's parameter values: its defaults with `params` changed."""
    return {s.name: s.default for s in all_specs()} | params


def saved_state(bag, values: dict) -> dict:
    """The state a node with these parameter values saves at the end of the record."""
    est = ThermalDriftEstimator(config_from_params(values))
    for chunk in read_chunks(bag, 60.0, streams=list(_INPUTS)):
        est.process(chunk)
    return est.get_state()


@dataclass(frozen=True)
class Restart:
    """The published yaw after a restart at `start_s`, at the truth stamps (s since the restart)."""
    start_s: float
    t_s: np.ndarray
    error_rad: np.ndarray        # wrap(published yaw - true yaw)
    sigma_rad: np.ndarray        # published yaw 1-sigma
    estimator: ThermalDriftEstimator

    def covered(self) -> np.ndarray:
        """Per truth sample: |error| <= the published 2-sigma."""
        return np.abs(self.error_rad) <= 2.0 * self.sigma_rad


def restart(bag, start_s: float, state: dict | None, values: dict, span_s: float = 600.0) -> Restart:
    """Run the node's code path from `start_s` (s since the record's first stamp) for `span_s`, warm
    started from `state` (None: cold)."""
    cfg = config_from_params(values)
    variance = OrientationVariance.from_params(values, cfg)
    comp = ThermalCompensator(cfg, values['output_delay_s'], held=lambda out, chunk: variance.held_tilt(
        out, chunk.imu.accel, comp.estimator.tilt_max_rate_rad_s))
    if state is not None:
        comp.estimator.set_state(state)
    rows, truth = [], []
    end_s = start_s + span_s
    with BagReader(bag) as reader:
        origin = reader.time_origin_ns
        for chunk in reader.chunks(10.0, streams=[*_INPUTS, 'odom']):
            if chunk.imu is not None and chunk.imu.t.size and chunk.imu.t[0] >= end_s:
                break
            part = {k: slice_samples(v, (v.t >= start_s) & (v.t < end_s)) for k, v in chunk.streams().items()}
            odom = part.get('odom')
            if odom is not None and odom.t.size:
                truth.append(np.column_stack((ns_at(odom.t, origin), euler_from_quat(odom.quat)[2])))
            feed = {k: v for k, v in part.items() if k in _INPUTS and v.t.size}
            if 'imu' not in feed:
                continue
            out = comp.run(SensorChunk(**feed), origin)
            if out is not None:
                rows.append(np.column_stack((out.ns, out.heading, variance.yaw_variance(out.heading_var)))[out.ok])
    if not rows or not truth:
        raise ValueError(f'{bag}: no IMU output or no /ground_truth/odom in [{start_s:g}, {end_s:g}) s')
    rows, truth = np.concatenate(rows), np.concatenate(truth)
    k = np.searchsorted(rows[:, 0], truth[:, 0])
    keep = k < len(rows)
    k, truth = k[keep], truth[keep]
    same = rows[k, 0] == truth[:, 0]          # the truth is stamped at IMU stamps
    k, truth = k[same], truth[same]
    return Restart(start_s, (truth[:, 0] - ns_at(np.array([start_s]), origin)[0]) * 1e-9,
                   wrap_angle(rows[k, 1] - truth[:, 1]), np.sqrt(rows[k, 2]), comp.estimator)
