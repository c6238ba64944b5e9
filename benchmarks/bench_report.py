"""What every benchmark records beside its figures: the machine, the code, its own RESULTS.md section."""
from __future__ import annotations

import platform
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS_MD = HERE / 'RESULTS.md'


def cpu_model() -> str:
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def code_state() -> dict:
    """The commit and whether the package had uncommitted changes (read-only git; None outside a clone)."""
    def git(*args):
        try:
            return subprocess.run(['git', *args], cwd=HERE.parent, capture_output=True, text=True,
                                  timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return None
    head = git('rev-parse', 'HEAD')
    dirty = git('status', '--porcelain', '--', 'gyro_thermal_comp')
    return {'git_head': head or None, 'package_uncommitted_changes': None if dirty is None else bool(dirty)}


def replace_section(title: str, section: str, path: Path = RESULTS_MD) -> None:
    """Put `section` (starting with the `## ` line `title`) in place of the one with that title, or
    at the end: each script writes its own section, never typed by hand."""
    text = path.read_text() if path.exists() else '# Benchmark results\n\nEach section is written by its script.\n'
    section = section.rstrip('\n') + '\n'
    start = text.find(title)
    if start >= 0:
        end = text.find('\n## ', start + 1)
        text = text[:start] + section + ('' if end < 0 else '\n' + text[end + 1:])
    else:
        text = text.rstrip('\n') + '\n\n' + section
    path.write_text(text)
