"""What a node says while it starts: what it does, inputs that have not arrived, and the still period
(no ROS here).

`stkf_start_message` is the STKF node's first line: what it does, from what, to where, and what it
needs first. A node that waits in silence looks broken: `InputWaitReport` names every input that has
sent nothing a few seconds after start (and whether anything publishes it), at most every `repeat_s`
per input; `StillPeriodReport` says when the motionless start period begins and ends, and warns when
motion cut it short. Both take the node's logger (anything with `info` and `warning`).
"""
from __future__ import annotations

import math
import time

from .orientation_uncertainty import declination_sigma_rad


def stkf_start_message(settings: dict, cfg, state_status: str, subscriptions, publishers) -> str:
    """The STKF node's start line from its parameter values, its EstimatorConfig, what its state file
    gave and its subscriptions and publishers (anything with a `topic_name`)."""
    s = settings
    declination = math.degrees(declination_sigma_rad(s['declination_sigma_rad'], cfg.declination_rad))
    tilt, deviation = math.degrees(s['tilt_floor_rad']), math.degrees(s['compass_deviation_sigma_rad'])
    inputs = ', '.join(sub.topic_name for sub in subscriptions)
    outputs = ', '.join(pub.topic_name for pub in publishers)
    return (f'thermal gyro-drift estimator, {state_status}. Inputs: {inputs}; outputs: {outputs}. '
            f'Needs {cfg.still_period_s:g} s motionless at the start (biases, compass noise). Orientation in '
            f"{s['world_frame'].upper()}, heading frame '{s['fixed_frame']}'"
            f"{', TF on' if s['publish_tf'] else ''}; 1-sigma floors: roll/pitch {tilt:.3g} deg, yaw "
            f"{math.hypot(deviation, declination):.2g} deg (compass "
            f"deviation {deviation:.3g}, declination {declination:.3g}"
            f"{'' if cfg.declination_rad else ': declination_rad not set'}).")


class InputWaitReport:
    def __init__(self, logger, topics: dict[str, str], *, optional=(), warn_after_s: float = 5.0,
                 repeat_s: float = 10.0, clock=time.monotonic):
        self.logger, self.topics, self.clock = logger, topics, clock   # topics: stream -> resolved topic name
        self.optional = set(optional)     # waited for only while something publishes them
        self.warn_after_s, self.repeat_s = warn_after_s, repeat_s
        self.t_start = clock()
        self._warned: dict[str, float] = {}
        self._arrived: set[str] = set()

    def check(self, received: dict[str, int], publishers: dict[str, int]) -> list[str]:
        """Warn about the inputs with nothing received yet (after `warn_after_s`); say once when one
        that was waited for arrives. Returns the streams still waited for."""
        now = self.clock()
        waiting = []
        for stream, topic in self.topics.items():
            if received.get(stream, 0) > 0:
                if stream in self._warned and stream not in self._arrived:
                    self.logger.info(f'data arrived on {topic}')
                self._arrived.add(stream)
                continue
            if now - self.t_start < self.warn_after_s or (stream in self.optional and not publishers.get(stream)):
                continue
            waiting.append(stream)
            if now - self._warned.get(stream, -math.inf) >= self.repeat_s:
                self._warned[stream] = now
                who = (f'{publishers.get(stream, 0)} publisher(s) matched' if publishers.get(stream, 0)
                       else 'no publisher: check the topic name and remappings')
                self.logger.warning(f'still waiting for data on {topic} after {now - self.t_start:.0f} s ({who})')
        return waiting


class StillPeriodReport:
    """Follows the estimator's still period by its stamps: begin (first sample), end (learning starts)."""

    def __init__(self, logger, still_period_s: float):
        self.logger, self.still_period_s = logger, still_period_s
        self.began_at: float | None = None
        self.done = False

    def update(self, estimator) -> None:
        """Say what changed since the last call (`estimator`: a ThermalDriftEstimator)."""
        t_origin, end_s, started = estimator.t_origin, estimator.still_end_s, estimator.learner is not None
        if t_origin is None or self.done:
            return
        if self.began_at is None:
            self.began_at = t_origin
            self.logger.info(f'still period began (stamp {t_origin:.3f} s): keep the unit motionless for '
                             f'{self.still_period_s:g} s while the gyro biases and the compass noise are measured')
        if started:
            self.done = True
            length = (end_s if end_s is not None else t_origin) - t_origin
            if length < self.still_period_s - 1e-6:
                self.logger.warning(f'still period cut short by motion after {length:.1f} s of '
                                    f'{self.still_period_s:g} s: the initial biases are less certain '
                                    '(restart motionless for a better start)')
            else:
                self.logger.info(f'still period complete ({length:.1f} s): estimating the drift')
