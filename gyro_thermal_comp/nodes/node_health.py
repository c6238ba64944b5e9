"""The STKF node's diagnostic level and message, in diagnostic_updater's sense (no ROS here).

- OK: the node works as designed. That includes the still period, coasting through a turn or a
  manoeuvre (the gate shuts for those by design), a short magnetic disturbance coasted on the model,
  a heading not known yet (a start on the move waits for a compass the gate passes), fixed
  parameters (`learn: false`), and a declared "no temperature sensor" (`temperature_sensor: false`:
  the constant drift only).
- WARN: degraded. The output is published but worse than the node promises: not learning (and
  why), the heading filter's own 1-sigma beyond the compass deviation it is corrected against (it
  coasted so long that the compass alone would do better), no compass, a temperature that is
  missing (not declared absent), stale or stuck, input samples dropped, a rejected state file, a
  parameter file that applies to nothing, endpoints that can never match.
- ERROR: broken. Nothing is compensated: no IMU data (none yet a few seconds after start, or the
  IMU went silent), or every IMU sample since the last report was dropped.

The message is the status (what the node does now) followed by every problem, each once.
`NotLearningNotice` says when to log, once, that the filter does not learn.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

OK, WARN, ERROR = 0, 1, 2
MOTION_REASONS = ('turn_rate', 'accel_norm', 'holdoff')   # the gate shuts for these by design


@dataclass
class NodeHealth:
    """What the node knows at a diagnostics tick (times in s, angles in deg)."""
    imu_topic: str = 'imu/data_raw'
    imu_received: int = 0
    imu_received_new: int = 0            # since the last report
    published_new: int = 0               # outputs published since the last report
    node_age_s: float = 0.0              # wall time since the node started
    silence_after_s: float = 2.0         # a stream this quiet is named
    silent: dict = field(default_factory=dict)   # {stream: silent for, s}
    started: bool = False                # the still period is over
    waiting: str = ''                    # the still period's own status while not started
    gate_open: bool = False
    gate_reasons: tuple = ()
    since_compass_s: float = 0.0         # since the last compass correction
    heading_sigma_deg: float = math.inf  # the heading filter's own 1-sigma
    heading_sigma_limit_deg: float = 3.0  # the compass deviation 1-sigma (compass_deviation_sigma_rad, in deg)
    temperature_sensor: bool = True      # declared present
    temperature_age_s: float = math.inf
    temperature_timeout_s: float = 10.0
    temperature_stuck: bool = False
    imu_for_s: float = 0.0               # stamp span of the IMU data so far
    learn: bool = True                   # false: fixed parameters (a calibration), nothing to learn
    filter_updates: int = 0
    not_learning: str | None = None      # LearningStatus verdict over the record
    stalled: str | None = None           # ... since the latest update
    state_rejected: bool = False
    parameter_files: tuple = ()          # files none of whose sections applies
    dropped_new: int = 0
    dropped_total: int = 0
    incompatible_endpoints: int = 0


UNKNOWN_HEADING_DEG = 179.0   # a heading sigma this wide is "unknown" (pi), not "uncertain"


def _status(h: NodeHealth) -> str:
    if not h.started:
        return h.waiting
    if h.heading_sigma_deg >= UNKNOWN_HEADING_DEG:
        return 'heading unknown: waiting for a compass sample the gate passes'
    if not h.gate_open:
        reasons = ','.join(h.gate_reasons) or 'none'
        if h.gate_reasons and set(h.gate_reasons) <= set(MOTION_REASONS):
            return f'coasting through a turn or manoeuvre ({reasons})'
        return f'coasting on the model: {reasons} for {h.since_compass_s:.0f} s'
    if not h.learn:
        return 'gate open: fixed drift parameters (learn: false)'
    if h.filter_updates == 0:
        return 'gate open, no drift update yet'
    if h.temperature_age_s == math.inf:
        return 'learning the constant drift only' + ('' if h.temperature_sensor else ' (no temperature sensor)')
    return 'learning: gate open'


def assess(h: NodeHealth) -> tuple[int, str]:
    """(level, message) of one diagnostics report."""
    problems: list[tuple[int, str]] = []
    if h.imu_received == 0:
        if h.node_age_s > h.silence_after_s:
            problems.append((ERROR, f'no IMU data on {h.imu_topic} after {h.node_age_s:.0f} s: nothing is published'))
    elif 'imu' in h.silent:
        problems.append((ERROR, f"IMU silent for {h.silent['imu']:.0f} s: nothing is published"))
    elif h.imu_received_new > 0 and h.published_new == 0 and h.dropped_new >= h.imu_received_new:
        problems.append((ERROR, f'every IMU sample since the last report was dropped ({h.dropped_new}): nothing '
                                'published (see core.* and input.*)'))
    if h.not_learning:
        problems.append((WARN, h.not_learning))
    elif h.stalled and h.gate_open:
        problems.append((WARN, h.stalled.replace('not learning', 'not learning any more', 1)))
    if h.started and h.heading_sigma_limit_deg < h.heading_sigma_deg < UNKNOWN_HEADING_DEG:
        problems.append((WARN, f'heading uncertain: 1-sigma {h.heading_sigma_deg:.1f} deg after '
                               f'{h.since_compass_s:.0f} s without a compass correction (beyond the compass '
                               f'deviation {h.heading_sigma_limit_deg:g} deg)'))
    if 'no_compass' in h.gate_reasons or 'mag' in h.silent:
        problems.append((WARN, 'no compass: heading from the gyro alone'))
    if h.temperature_sensor:
        started_long_ago = h.started or h.imu_for_s > h.silence_after_s
        if h.temperature_age_s == math.inf and started_long_ago:
            problems.append((WARN, 'no temperature readings: the model runs at its reference temperature '
                                   '(temperature_sensor false if the IMU has none)'))
        elif math.isfinite(h.temperature_age_s) and h.temperature_age_s > h.temperature_timeout_s:
            problems.append((WARN, f'temperature stale for {h.temperature_age_s:.0f} s: not learning, drift '
                                   'uncertainty growing'))
    if h.temperature_stuck:
        problems.append((WARN, 'temperature stuck'))
    if h.state_rejected:
        problems.append((WARN, 'state file rejected (see state_file)'))
    problems += [(WARN, p) for p in h.parameter_files]
    others = {k: v for k, v in h.silent.items() if k not in ('imu', 'mag')}
    if others:
        problems.append((WARN, 'no input on ' + ', '.join(f'{k} for {v:.0f} s' for k, v in others.items())))
    if h.dropped_new > 0:
        problems.append((WARN, f'{h.dropped_new} input samples dropped since the last report '
                               f'({h.dropped_total} in all: see core.* and input.*)'))
    if h.incompatible_endpoints:
        problems.append((WARN, f'{h.incompatible_endpoints} endpoint(s) that can never match (see the log)'))
    level = max([OK] + [lvl for lvl, _ in problems])
    return level, '; '.join([_status(h)] + [text for _, text in problems])


class NotLearningNotice:
    """When to say in the log that the filter does not learn, or stalled with the gate open: once,
    and again only after it has learned since."""

    def __init__(self):
        self._said_at: int | None = None   # filter updates when it was said

    def due(self, h: NodeHealth) -> str | None:
        """The line to log now, or None."""
        said = h.not_learning or (h.stalled if h.gate_open else None)
        if said and self._said_at is None:
            self._said_at = h.filter_updates
            return said
        if self._said_at is not None and h.filter_updates > self._said_at:
            self._said_at = None
        return None
