"""Why the compass is not used at a sample: one bit per reason, in one place.

Each reason's bit is fixed by its name, not by its position in a list: records, diagnostics and
saved figures keep their meaning when a reason is added. The magnetic gate's tests (gate_tests.py)
own bits 0-5, the estimator's own reasons bits 6-12; a gate test added later registers its own
free bit (`register_reason`)."""
from __future__ import annotations

REASON_BIT: dict[str, int] = {
    # the magnetic gate
    'field_norm': 1 << 0, 'dip_angle': 1 << 1, 'heading_rate_mismatch': 1 << 2, 'turn_rate': 1 << 3,
    'accel_norm': 1 << 4, 'holdoff': 1 << 5,
    # the estimator
    'heading_innovation': 1 << 6, 'no_compass': 1 << 7, 'time_gap': 1 << 8, 'temperature_stuck': 1 << 9,
    'still_period': 1 << 10, 'dropped_input': 1 << 11, 'temperature_stale': 1 << 12,
}
GATE_REASONS = ('field_norm', 'dip_angle', 'heading_rate_mismatch', 'turn_rate', 'accel_norm', 'holdoff')
ESTIMATOR_REASONS = ('heading_innovation', 'no_compass', 'time_gap', 'temperature_stuck', 'still_period',
                     'dropped_input', 'temperature_stale')
REASONS = GATE_REASONS + ESTIMATOR_REASONS


def register_reason(name: str, bit: int) -> int:
    """A new reason `name` on bit number `bit`; returns its mask. Registering the same name on the
    same bit again is allowed; a name or a bit already taken otherwise raises ValueError."""
    mask = 1 << int(bit)
    if REASON_BIT.get(name, mask) != mask:
        raise ValueError(f'reason {name!r} already has bit {REASON_BIT[name].bit_length() - 1}')
    taken = {m: n for n, m in REASON_BIT.items()}
    if taken.get(mask, name) != name:
        raise ValueError(f'bit {bit} is already the reason {taken[mask]!r}')
    REASON_BIT[name] = mask
    return mask


def unregister_reason(name: str) -> None:
    """Remove a reason `register_reason` added (the built-in ones stay)."""
    if name not in REASONS:
        REASON_BIT.pop(name, None)


def reasons_by_bit() -> list[tuple[str, int]]:
    """Every reason known now (registered gate tests included) with its mask, in bit order."""
    return sorted(REASON_BIT.items(), key=lambda kv: kv[1])


def reason_names(mask: int) -> list[str]:
    """Names of the reasons set in a reason bit mask, in bit order."""
    return [name for name, bit in reasons_by_bit() if int(mask) & bit]
