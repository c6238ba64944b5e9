"""Why the compass is not used at a sample: one bit per reason, in one place.

The magnetic gate's tests come first (magnetic_gate.py), then the estimator's own reasons."""
from __future__ import annotations

GATE_REASONS = ('field_norm', 'dip_angle', 'heading_rate_mismatch', 'turn_rate', 'accel_norm', 'holdoff')
ESTIMATOR_REASONS = ('heading_innovation', 'no_compass', 'time_gap', 'temperature_stuck', 'still_period',
                     'dropped_input', 'temperature_stale')
REASONS = GATE_REASONS + ESTIMATOR_REASONS
REASON_BIT = {name: 1 << i for i, name in enumerate(REASONS)}


def reason_names(mask: int) -> list[str]:
    """Names of the reasons set in a reason bit mask."""
    return [name for name in REASONS if int(mask) & REASON_BIT[name]]
