"""Many units' logs at once: group the logs by unit, calibrate each unit in parallel (processes on
this machine, or the workers of a Dask distributed cluster), write one output folder per unit.

A unit's key comes from the log's file name (a regular expression: its first group, or the whole
match) or from a field the log carries about itself (`field:NAME`, `Source.metadata`: a ULog's
`sys_uuid` or `param.*`, a DataFlash log's `param.*`, a netCDF file's global attributes, a
simulated bag's `sim.*`). Workers only read logs and return plain data; this process writes every
file, so a cluster needs the logs where its workers can read them and nothing else.

Per unit: `drift_model.yaml` (thermal/model_file.py), `stkf_state.json` (nodes/state_store.py),
`report.md` and `report.png` (report.py), `calibration.json` (the figures, for scripts).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from ..sources import open_source
from .unit import CalibrationError, UnitCalibration, calibrate_unit

FILES = {'model': 'drift_model.yaml', 'state': 'stkf_state.json', 'report': 'report.md', 'figure': 'report.png',
         'summary': 'calibration.json'}
SINGLE_UNIT = 'unit'


@dataclass
class UnitOutcome:
    unit: str
    logs: list
    folder: Path | None = None
    calibration: UnitCalibration | None = None
    error: str | None = None


def unit_key(path, unit: str | None, source_options: dict | None = None) -> str:
    """The unit a log belongs to (module docstring); CalibrationError if it cannot be told."""
    if not unit:
        return SINGLE_UNIT
    if unit.startswith('field:'):
        name = unit[len('field:'):]
        with open_source(path, **(source_options or {})) as src:
            if name not in src.metadata:
                known = ', '.join(sorted(src.metadata)[:12])
                raise CalibrationError(f'{path}: no field {name!r} (it has: {known or "none"})')
            return _safe(str(src.metadata[name]))
    try:
        match = re.search(unit, Path(path).name)
    except re.error as exc:
        raise CalibrationError(f'--unit {unit!r}: not a regular expression ({exc})') from None
    if match is None:
        raise CalibrationError(f'{path}: its name does not match --unit {unit!r}')
    return _safe(match.group(1) if match.groups() else match.group(0))


def _safe(key: str) -> str:
    """A unit key as a folder name."""
    text = re.sub(r'[^A-Za-z0-9_.-]+', '_', key.strip()).strip('._')
    if not text:
        raise CalibrationError(f'unit key {key!r} gives no usable folder name')
    return text


def group_logs(logs, unit: str | None = None, source_options: dict | None = None) -> dict[str, list[str]]:
    groups: dict[str, list[str]] = {}
    for path in logs:
        groups.setdefault(unit_key(path, unit, source_options), []).append(str(path))
    return groups


def unit_outputs(cal: UnitCalibration) -> dict:
    """What a worker returns for a unit: the calibration and its rendered report."""
    from .report import figure_png, markdown
    return {'calibration': cal, 'figure': figure_png(cal), 'report': markdown(cal, FILES)}


def _task(unit: str, logs: list[str], source_options: dict | None, reference: str) -> dict:
    """One unit on a worker: outputs, or {'error': one line} for logs that cannot calibrate it."""
    from ..bag_io import BagError
    try:
        return unit_outputs(calibrate_unit(logs, unit=unit, source_options=source_options, reference=reference))
    except (CalibrationError, BagError, ValueError, OSError) as exc:
        return {'error': ' '.join(str(exc).split()) or type(exc).__name__}


def run_tasks(groups: dict[str, list[str]], *, source_options=None, reference='auto', jobs: int | None = None,
              scheduler: str | None = None) -> dict[str, dict]:
    """unit -> _task result, in parallel: on the Dask cluster at `scheduler`, else in `jobs` processes
    (default: one per unit, at most one per core)."""
    units = list(groups)
    args = [(u, groups[u], source_options, reference) for u in units]
    if scheduler:
        from dask.distributed import Client
        try:
            client = Client(scheduler, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise CalibrationError(f'--scheduler {scheduler}: cannot connect ({exc})') from None
        with client:
            futures = [client.submit(_task, *a, key=f'calibrate-{a[0]}', pure=False) for a in args]
            return dict(zip(units, client.gather(futures)))
    jobs = max(1, min(len(units), jobs or os.cpu_count() or 1))
    if jobs == 1:
        return {u: _task(*a) for u, a in zip(units, args)}
    # forkserver: workers fork from a clean single-threaded server that has imported the package once
    # (fork from a caller with threads can deadlock; spawn imports numpy, scipy, ... in every worker)
    ctx = get_context('forkserver')
    ctx.set_forkserver_preload([__name__, 'gyro_thermal_comp.calibration.unit', 'gyro_thermal_comp.discrepancy',
                                'gyro_thermal_comp.thermal.estimator', 'matplotlib.figure'])
    with ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
        return dict(zip(units, pool.map(_task, *zip(*args))))


def write_unit(folder: Path, outputs: dict, overwrite: bool) -> Path:
    """A unit's files, into a folder that appears only when complete."""
    from ..nodes.state_store import StateStore
    from ..thermal.model_file import DriftModelFile
    cal: UnitCalibration = outputs['calibration']
    if folder.exists() and not overwrite and any(folder.iterdir()):
        raise CalibrationError(f'output {folder} already exists and is not empty (use --force to overwrite)')
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f'.{folder.name}.', suffix='.partial', dir=folder.parent))
    try:
        DriftModelFile.from_dict(cal.model).save(tmp / FILES['model'])
        store = StateStore(tmp / FILES['state'])
        with store:
            store.save(cal.state)
        store.lock_path.unlink(missing_ok=True)
        (tmp / FILES['figure']).write_bytes(outputs['figure'])
        (tmp / FILES['report']).write_text(outputs['report'])
        (tmp / FILES['summary']).write_text(json.dumps(summary(cal), indent=1, sort_keys=True) + '\n')
        if folder.exists():
            shutil.rmtree(folder)
        os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def summary(cal: UnitCalibration) -> dict:
    from .report import residual_rms_deg_s
    return {'unit': cal.unit, 'logs': cal.logs, 'terms': cal.state['terms'],
            'coefficients': {k: {'value': v, 'sigma': s} for k, (v, s) in cal.coefficients().items()},
            'residual_rms_deg_s': residual_rms_deg_s(cal), 'drift_series': cal.drift['kind'], 'notes': cal.notes,
            'model_inputs': cal.model.get('inputs', {}), 'coverage': cal.state.get('coverage')}


def calibrate_fleet(logs, out, *, unit: str | None = None, source_options: dict | None = None,
                    reference: str = 'auto', jobs: int | None = None, scheduler: str | None = None,
                    overwrite: bool = False) -> list[UnitOutcome]:
    """Calibrate every unit of `logs` into `out` (one unit, no `unit` key: `out` itself; else
    `out/<unit>`). Units whose logs cannot be used come back with `error` set; the others are written."""
    out = Path(out)
    groups = group_logs(logs, unit, source_options)
    results = run_tasks(groups, source_options=source_options, reference=reference, jobs=jobs, scheduler=scheduler)
    outcomes = []
    for name, result in results.items():
        outcome = UnitOutcome(name, groups[name])
        if 'error' in result:
            outcome.error = result['error']
        else:
            outcome.calibration = result['calibration']
            outcome.folder = write_unit(out if unit is None else out / name, result, overwrite)
        outcomes.append(outcome)
    return outcomes
