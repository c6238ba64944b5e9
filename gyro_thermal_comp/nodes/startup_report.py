"""What a node says while it starts: inputs that have not arrived, and the still period (no ROS here).

A node that waits in silence looks broken: `InputWaitReport` names every input that has sent nothing
a few seconds after start (and whether anything publishes it), at most every `repeat_s` per input;
`StillPeriodReport` says when the motionless start period begins and ends, and warns when motion
cut it short. Both take the node's logger (anything with `info` and `warning`).
"""
from __future__ import annotations

import math
import time


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

    def update(self, t_origin: float | None, end_s: float | None, started: bool) -> None:
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
