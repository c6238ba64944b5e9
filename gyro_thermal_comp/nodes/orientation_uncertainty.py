"""1-sigma of the orientation the STKF node publishes (REP 145 covariances), pure numpy.

Roll and pitch are the direction of the MEAN specific force over the trailing `tilt_window_s`
(thermal/imu_stretch.py: 120 s without turning samples), not a real-time attitude. Their error has
parts no noise model of the accelerometer shows:
- a floor: the accelerometer's zero-g offset (1 mg ~ 0.057 deg) and its axes' misalignment are
  constant, no averaging removes them (`tilt_floor_rad`);
- what the vehicle's own accelerations leave in the mean: the window's specific force is gravity
  plus the mean of the vehicle's accelerations (speeding up, braking, climbing). Its standard error
  is measured from the scatter of block means of the accelerometer direction over the window
  (batch means: blocks long enough that a manoeuvre is correlated within a block, not across).
The real-time attitude's departure from the window mean (a vehicle leaning in a turn, a boat
rolling, a slope just reached) cannot be told from a horizontal acceleration by an accelerometer
and is not covered: where it matters, take roll/pitch from an attitude filter.

Yaw: the heading filter's sigma (angle random walk, drift, coasting, compass noise) plus what the
compass cannot know and never averages down: its deviation at the start heading (hard/soft iron
left after calibration) and the error of the declination the node was given.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..angles import wrap_angle
from ..thermal.compass import roll_pitch_from_accel

# Declination error when the parameter is unset: a value from a field model (WMM/IGRF) is good to
# about half a degree away from magnetic anomalies; declination_rad left at 0 means the local
# declination is unknown, and it is 10-20 deg over much of the inhabited world.
DECLINATION_MODEL_SIGMA_RAD = math.radians(0.5)
DECLINATION_UNKNOWN_SIGMA_RAD = math.radians(10.0)


def declination_sigma_rad(sigma_rad: float | None, declination_rad: float) -> float:
    """The declination's 1-sigma, rad: the parameter if set, else by whether a declination was given."""
    if sigma_rad is not None and math.isfinite(sigma_rad):
        return float(sigma_rad)
    return DECLINATION_MODEL_SIGMA_RAD if declination_rad != 0.0 else DECLINATION_UNKNOWN_SIGMA_RAD


@dataclass(frozen=True)
class OrientationFloors:
    """What no averaging removes, as 1-sigma."""
    tilt_rad: float           # roll and pitch: accelerometer offset and misalignment
    heading_rad: float        # yaw: compass deviation and declination error, combined

    @classmethod
    def from_sigmas(cls, tilt_rad: float, deviation_rad: float, declination_rad: float) -> 'OrientationFloors':
        return cls(tilt_rad, math.hypot(deviation_rad, declination_rad))


class TiltScatter:
    """Standard error (rad) of the window-mean roll and pitch, from the scatter of `block_s` block
    means of the specific force over the trailing `window_s`. Blocks lie on the absolute time grid
    and only completed ones count, so the value at a sample depends on the stamps alone (any
    chunking gives the same). Samples with `use` False (turning: centripetal force) stay out, as
    they stay out of the estimator's mean."""

    def __init__(self, window_s: float, block_s: float = 10.0):
        self.block_s = float(block_s)
        self.n_blocks = max(1, int(round(window_s / block_s)))
        self.blocks: deque = deque()            # (block id, sum (3,), count) of completed blocks
        self.cur_id: int | None = None
        self.cur_rows: list[np.ndarray] = []    # the current block's samples: summed once, when it
        self.se = (0.0, 0.0)                    # completes (the same sum whatever the chunking)

    def update(self, t: np.ndarray, accel: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample standard error of roll and pitch, rad (0 until two blocks are complete)."""
        roll_se, pitch_se = np.empty(t.size), np.empty(t.size)
        ids = np.floor(t / self.block_s).astype(np.int64)
        starts = np.flatnonzero(np.diff(ids, prepend=ids[0] - 1) != 0) if t.size else np.empty(0, int)
        for k, i0 in enumerate(starts):
            i1 = starts[k + 1] if k + 1 < starts.size else t.size
            if self.cur_id is not None and ids[i0] != self.cur_id:
                self._complete(int(ids[i0]))
            self.cur_id = int(ids[i0])
            self.cur_rows.append(accel[i0:i1][use[i0:i1]])
            roll_se[i0:i1], pitch_se[i0:i1] = self.se
        return roll_se, pitch_se

    def _complete(self, new_id: int) -> None:
        rows = np.concatenate(self.cur_rows)
        self.cur_rows = []
        if new_id < self.cur_id:    # the clock went back (bag loop): a new record
            self.blocks.clear()
        elif len(rows):
            self.blocks.append((self.cur_id, rows.sum(axis=0), len(rows)))
        while self.blocks and self.blocks[0][0] <= new_id - self.n_blocks:
            self.blocks.popleft()
        self.se = _batch_mean_error(self.blocks)


def _batch_mean_error(blocks) -> tuple[float, float]:
    """Standard error of the roll and pitch of the pooled mean, from the spread of the block means
    about it (count-weighted; effective number of blocks k = (sum n)^2 / sum n^2)."""
    if len(blocks) < 2:
        return 0.0, 0.0
    n = np.array([b[2] for b in blocks], dtype=float)
    sums = np.array([b[1] for b in blocks])
    roll0, pitch0 = roll_pitch_from_accel(sums.sum(axis=0) / n.sum())
    roll, pitch = roll_pitch_from_accel(sums / n[:, None])
    k_eff = n.sum() ** 2 / np.sum(n ** 2)
    scale = 1.0 / (n.sum() * (k_eff - 1.0))
    return (math.sqrt(float(np.sum(n * wrap_angle(roll - roll0) ** 2)) * scale),
            math.sqrt(float(np.sum(n * wrap_angle(pitch - pitch0) ** 2)) * scale))


class OrientationVariance:
    """Per-sample variances (rad^2) of roll, pitch and yaw for the node's outputs."""

    def __init__(self, floors: OrientationFloors, tilt_window_s: float):
        self.floors = floors
        self.scatter = TiltScatter(tilt_window_s)

    @classmethod
    def from_params(cls, values: dict, cfg) -> 'OrientationVariance':
        """As the node builds it from its parameter values and its EstimatorConfig."""
        declination = declination_sigma_rad(values['declination_sigma_rad'], cfg.declination_rad)
        return cls(OrientationFloors.from_sigmas(values['tilt_floor_rad'], values['compass_deviation_sigma_rad'],
                                                 declination), cfg.tilt_window_s)

    def update(self, t: np.ndarray, accel: np.ndarray, gyro_compensated: np.ndarray, valid: np.ndarray,
               heading_sigma_rad: np.ndarray, turn_rate_rad_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Roll, pitch and yaw variances, rad^2, one per sample (dropped samples included). Samples
        turning faster than `turn_rate_rad_s` stay out of the tilt scatter, as out of the tilt."""
        use = valid & (np.abs(gyro_compensated[:, 2]) < turn_rate_rad_s) & np.all(np.isfinite(accel), axis=1)
        roll_se, pitch_se = np.zeros(t.size), np.zeros(t.size)
        roll_se[valid], pitch_se[valid] = self.scatter.update(t[valid], accel[valid], use[valid])
        tilt2 = self.floors.tilt_rad ** 2
        sigma = np.where(np.isfinite(heading_sigma_rad), heading_sigma_rad, math.pi)
        return tilt2 + roll_se ** 2, tilt2 + pitch_se ** 2, np.square(sigma) + self.floors.heading_rad ** 2

    def held_tilt(self, out, accel: np.ndarray, turn_rate_rad_s: float) -> dict[str, np.ndarray]:
        """Roll and pitch variances (rad^2) at the estimator's rows (`ThermalOutput`), which the fast
        path carries to the outputs anchored there; pi^2 where no tilt is known yet."""
        roll_var, pitch_var, _ = self.update(out.track.t, accel, out.gyro_compensated, out.valid,
                                             out.track.heading_sigma_rad, turn_rate_rad_s)
        known = np.isfinite(out.roll_rad) & np.isfinite(out.pitch_rad)
        return {'roll_var': np.where(known, roll_var, math.pi ** 2), 'pitch_var': np.where(known, pitch_var, math.pi ** 2)}

    def yaw_variance(self, heading_var_rad2: np.ndarray) -> np.ndarray:
        """Yaw variance, rad^2, of an output heading with the given filter variance."""
        if np.ndim(heading_var_rad2) == 0:   # one sample (a live node): plain floats
            v = float(heading_var_rad2)
            return (v if math.isfinite(v) else math.pi ** 2) + self.floors.heading_rad ** 2
        return np.where(np.isfinite(heading_var_rad2), heading_var_rad2, math.pi ** 2) + self.floors.heading_rad ** 2
