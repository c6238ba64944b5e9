"""Progress bars for long runs (tqdm on stderr; silent when stderr is not a terminal)."""
from __future__ import annotations

import sys

from tqdm import tqdm


class _Bar(tqdm):
    def update_to(self, value: float) -> None:
        """Move the bar to an absolute position (e.g. seconds of data processed)."""
        self.update(max(0.0, value - self.n))


def progress(total: float | None, unit: str = 's', desc: str = '') -> _Bar:
    return _Bar(total=total, unit=unit, desc=desc, disable=not sys.stderr.isatty(), leave=False,
                bar_format='{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} {unit} [{elapsed}<{remaining}]')
