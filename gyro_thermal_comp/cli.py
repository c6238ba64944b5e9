"""`gyro-thermal-comp`: one command line over the package (simulate, inspect, bundle, demo).

Bad input gets one line on stderr and a non-zero exit, never a traceback: every subcommand raises
`CliError` (or BagError / ValueError from the layers below) and `main` prints it. An unusable bag
(not a bag, nothing readable on the expected topics, a known topic with the wrong type) is a BagError;
a bag read only in part (truncated) is a BagWarning, printed as one `warning:` line per bag.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import tempfile
import warnings
from pathlib import Path

PROG = 'gyro-thermal-comp'
EXIT_BAD_INPUT = 2


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, not argparse's usage block
        raise CliError(f'{self.prog.split()[-1]}: {message}' if ' ' in self.prog else message)


def _key_value(text: str) -> tuple[str, float]:
    key, sep, value = text.partition('=')
    if not sep or not key:
        raise argparse.ArgumentTypeError(f'expected NAME=VALUE, got {text!r}')
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f'value of {key} must be a number, got {value!r}') from None
    if not math.isfinite(number):
        raise argparse.ArgumentTypeError(f'value of {key} must be finite, got {value!r}')
    return key, number


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'must be a positive number, got {text!r}')
    return value


def _add_source_options(p, *, window: bool = False) -> None:
    """The options every command that reads a recording takes (gyro_thermal_comp/sources, docs/sources.md)."""
    p.add_argument('--topic', action='append', default=[], metavar='STREAM=/TOPIC',
                   help='ROS bags: read STREAM (imu, mag, temperature, odom, ... or a node topic name such as '
                        'imu/data_raw) from TOPIC; repeatable, as node remaps')
    p.add_argument('--map', type=Path, metavar='FILE', help='tables (CSV, netCDF, HDF5): the column map (YAML)')
    p.add_argument('--imu', type=int, metavar='N', help='flight logs: the IMU instance to read (default: the first '
                                                        'with a temperature)')
    if window:
        p.add_argument('--start', metavar='TIME', help='from TIME: s since the first sample, or UTC (ISO 8601)')
        p.add_argument('--end', metavar='TIME', help='up to TIME: s since the first sample, or UTC (ISO 8601)')
        p.add_argument('--period', metavar='NAME', help="a named time range of the column map's periods")


def _source_options(args) -> dict:
    opts = {'topic_map': args.topic or None, 'column_map': args.map, 'imu': args.imu}
    for key in ('start', 'end', 'period'):
        if getattr(args, key, None) is not None:
            opts[key] = getattr(args, key)
    return opts


def _is_own_bag(path: Path, opts: dict) -> bool:
    """A ROS 2 bag read with the package's topic names (every command's original path)."""
    from .sources import detect_kind
    return not any(opts.values()) and detect_kind(path) == 'rosbag2'


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f'must be a number >= 0, got {text!r}')
    return value


# ---------------------------------------------------------------- simulate
def _add_simulate(sub):
    p = sub.add_parser('simulate', help='simulate a scenario into a rosbag2 (mcap) folder')
    p.add_argument('scenario', help='scenario name (see `simulate --list`)', nargs='?')
    p.add_argument('--out', type=Path, help='output bag folder (must not exist unless --force)')
    p.add_argument('--seed', type=int, default=0, help='random seed: same seed, same bag (default 0)')
    p.add_argument('--unit-seed', type=int, default=None,
                   help='draw the sensor unit from this seed instead (the same unit on another run: a calibration)')
    p.add_argument('--duration', type=_positive, default=None, help='duration in s (default: scenario)')
    p.add_argument('--effect', type=_key_value, action='append', default=[], metavar='NAME=VALUE',
                   help='switch an effect on/off or resize it (0 = off); repeatable')
    p.add_argument('--param', type=_key_value, action='append', default=[], metavar='KEY=VALUE',
                   help='override a scenario parameter (e.g. spin_hz=4); repeatable')
    p.add_argument('--imu-rate', type=_positive, help='IMU sample rate, Hz')
    p.add_argument('--mag-rate', type=_positive, help='magnetometer sample rate, Hz')
    p.add_argument('--temp-rate', type=_positive, help='temperature sample rate, Hz')
    p.add_argument('--truth-rate', type=_positive, help='ground-truth topics rate, Hz')
    p.add_argument('--list', action='store_true', help='list scenarios and effects, then exit')
    p.add_argument('--force', action='store_true', help='overwrite an existing output bag')
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args) -> int:
    from . import sim
    if args.list:
        print('scenarios:')
        for name, text in sim.SCENARIOS.items():
            print(f'  {name:22s} {text}')
        print('effects (--effect NAME=VALUE, 0 = off):')
        for name, spec in sim.EFFECTS.items():
            print(f'  {name:22s} [{spec.unit}] default {spec.default:g}: {spec.description}')
        return 0
    if not args.scenario or args.out is None:
        raise CliError('simulate: SCENARIO and --out BAG are required')
    config = sim.make_config(args.scenario, seed=args.seed, duration_s=args.duration,
                             effects=dict(args.effect) or None, params=dict(args.param) or None,
                             imu_rate_hz=args.imu_rate, mag_rate_hz=args.mag_rate,
                             temp_rate_hz=args.temp_rate, truth_rate_hz=args.truth_rate, unit_seed=args.unit_seed)
    counts = write_simulation(config, args.out, overwrite=args.force)
    print(f'wrote {args.out}: ' + ', '.join(f'{t} {n}' for t, n in counts.items()))
    return 0


def write_simulation(config, out: Path, *, overwrite: bool = False) -> dict[str, int]:
    """Stream a simulation into a bag; the first message records the full config as JSON."""
    from . import sim, topics
    from .bag_io import BagWriter
    from .progress import progress
    with BagWriter(out, overwrite=overwrite, covariances=sim.covariances(config),
                   time_origin_ns=sim.EPOCH_NS) as writer:   # simulator time 0 is stamped EPOCH_NS
        writer.write_text(topics.SIM_CONFIG, 0.0, json.dumps(config.to_dict(), sort_keys=True))
        with progress(total=config.duration_s, unit='s', desc=f'simulate {config.scenario}') as bar:
            for chunk in sim.simulate(config):
                writer.write_chunk(chunk)
                if chunk.imu is not None and len(chunk.imu.t):
                    bar.update_to(float(chunk.imu.t[-1]))
    return writer.counts


# ---------------------------------------------------------------- info
def _add_info(sub):
    p = sub.add_parser('info', help='summarise a bag: topics, counts, rates, temperature range')
    p.add_argument('bags', nargs='+', type=Path)
    p.add_argument('--json', action='store_true', help='print JSON instead of a table')
    _add_source_options(p)
    p.set_defaults(func=cmd_info)


def cmd_info(args) -> int:
    from .bag_summary import summarize_bag
    opts = _source_options(args)
    if not all(_is_own_bag(path, opts) for path in args.bags):   # other formats: what the reader found
        from .sources import open_source
        for path in args.bags:
            with open_source(path, **opts) as source:
                print('\n'.join([source.describe(), *(f'  {n}' for n in source.notes),
                                  f'  {source.duration_s:.1f} s; {source.dropped.to_text()}']))
        return 0
    summaries = [summarize_bag(path) for path in args.bags]
    if args.json:
        print(json.dumps([s.to_dict() for s in summaries], indent=2))
    else:
        for s in summaries:
            print(s.to_text())
    return 0


# ---------------------------------------------------------------- bundle
MANIFEST = 'manifest.json'


def _add_bundle(sub):
    p = sub.add_parser('bundle', help='regenerate the bundled bags from FOLDER/manifest.json')
    p.add_argument('folder', type=Path)
    p.add_argument('--only', action='append', default=[], help='regenerate only this bag (repeatable)')
    p.add_argument('--out', type=Path, help='write into this folder instead of FOLDER')
    p.add_argument('--force', action='store_true', help='overwrite existing bags')
    p.set_defaults(func=cmd_bundle)


def load_manifest(folder: Path) -> list[dict]:
    path = folder / MANIFEST
    try:
        entries = json.loads(path.read_text())['bags']
    except FileNotFoundError:
        raise CliError(f'no {MANIFEST} in {folder}') from None
    except (ValueError, KeyError, TypeError) as exc:
        raise CliError(f'{path} is not a valid manifest: {exc}') from None
    return entries


def cmd_bundle(args) -> int:
    out_folder = args.out or args.folder
    for entry in load_manifest(args.folder):
        if args.only and entry['name'] not in args.only:
            continue
        argv = shlex.split(entry['command'])
        if argv[:2] != [PROG, 'simulate']:
            raise CliError(f'manifest command for {entry["name"]} is not a `{PROG} simulate` command')
        sim_args = build_parser().parse_args(argv[1:] + ['--out', str(out_folder / entry['name'])]
                                             + (['--force'] if args.force else []))
        cmd_simulate(sim_args)
    return 0


# ---------------------------------------------------------------- demo
# bundled bag -> the bundled calibration run of the same unit (bags/manifest.json: --unit-seed)
DEMO_CALIBRATIONS = {'static_ramp_outages': 'static_ramp_unit2'}

def _add_demo(sub):
    p = sub.add_parser('demo', help='the main job on the bundled bags (summary; evaluation when present)')
    p.add_argument('folder', type=Path, nargs='?', default=Path('bags'))
    p.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    """Summaries, the side-by-side evaluation of every bag with ground truth, and node replays."""
    from .bag_summary import summarize_bag
    from .nodes.replay import replay
    bags = sorted(p for p in args.folder.iterdir() if (p / 'metadata.yaml').is_file()) if args.folder.is_dir() else []
    if not bags:
        raise CliError(f'no bags found in {args.folder}')
    summaries = {path.name: summarize_bag(path) for path in bags}
    print(f'== bundled bags in {args.folder}')
    for s in summaries.values():
        print(s.to_text().splitlines()[0])
    for path in bags:
        if path.name.startswith('carousel'):
            continue
        cal = args.folder / DEMO_CALIBRATIONS.get(path.name, '')
        if path.name in DEMO_CALIBRATIONS and (cal / 'metadata.yaml').is_file():
            # the loop closed: calibrate on another run of the same unit, name what the model misses,
            # run the STKF with it (stkf_model) beside the default one and the calibrated MLR
            from .discrepancy import discover
            from .discrepancy.model_export import model_file_from_discovery
            model = model_file_from_discovery(discover(cal), str(cal))
            print(f'\n== evaluate {path} with a calibration and a discovered model  (gyro-thermal-comp discover {cal} '
                  f'--write-model MODEL; gyro-thermal-comp evaluate {path} --calibration {cal} --model MODEL)')
            print(f"model: {', '.join(model.names)}; inputs {model.to_dict()['inputs']}")
            print(evaluate_bag(path, calibration=mlr_calibration(cal), model_file=model).to_text())
        else:
            print(f'\n== evaluate {path}  (gyro-thermal-comp evaluate {path})')
            print(evaluate_bag(path).to_text())
    with tempfile.TemporaryDirectory() as tmp:
        for path in bags:
            kind = 'carousel' if path.name.startswith('carousel') else 'stkf'
            if kind == 'stkf' and path.name != 'vehicle_loop':
                continue
            out = Path(tmp) / f'{path.name}_{kind}'
            counts = replay(path, out, node=kind)
            outputs = {t: n for t, n in counts.items() if t in ('/imu/data', '/imu/heading', '/imu/demodulated',
                                                              '/carousel/gyro_bias', '/diagnostics')}
            print(f'\n== replay {path} through {kind}_node (gyro-thermal-comp replay {path} --node {kind} --out OUT): '
                  + ', '.join(f'{t} {n}' for t, n in outputs.items()))
    return 0


# ---------------------------------------------------------------- evaluate
def _add_evaluate(sub):
    p = sub.add_parser('evaluate', help='heading and drift error of every method against the ground truth')
    p.add_argument('bag', type=Path)
    p.add_argument('--json', action='store_true', help='print JSON instead of the table')
    p.add_argument('--plots', type=Path, metavar='DIR', help='write PNG figures into DIR')
    p.add_argument('--no-peers', action='store_true', help='skip the imufusion / ahrs peers (faster)')
    p.add_argument('--arw', type=float, default=0.04, metavar='DEG_SQRT_S',
                   help="the gyro's angle random walk, deg/sqrt(s), for the outage information floor "
                        '(default 0.04, ADXRS623 class)')
    cal = p.add_mutually_exclusive_group()
    cal.add_argument('--calibration', type=Path, metavar='BAG',
                     help='calibrate `mlr` on this other run of the same unit (needs /imu/data_raw, /imu/mag, '
                          '/imu/temperature), then apply it fixed; without a calibration `mlr` is not applicable')
    cal.add_argument('--calibration-file', type=Path, metavar='FILE',
                     help='apply the MLR calibration in FILE (YAML, written by --save-calibration)')
    p.add_argument('--save-calibration', type=Path, metavar='FILE',
                   help='with --calibration BAG: also write the fitted calibration to FILE')
    p.add_argument('--model', type=Path, metavar='FILE',
                   help='also run the STKF with this drift model file (discover --write-model) as stkf_model')
    _add_source_options(p)
    p.set_defaults(func=cmd_evaluate)


def mlr_calibration(bag: Path | None = None, file: Path | None = None):
    """The `MlrCalibration` fitted on `bag` or read from `file` (None without either); bad input is a
    CliError or BagError (one line)."""
    from .bag_io import BagReader, read_chunks
    from .thermal.baselines import CalibrationError, MlrCalibration, NotApplicable
    if file is not None:
        try:
            return MlrCalibration.load(file)
        except CalibrationError as exc:
            raise CliError(str(exc)) from None
    if bag is None:
        return None
    with BagReader(bag) as reader:   # BagError: missing, not a bag, unreadable
        missing = sorted({'imu', 'mag', 'temperature'} - set(reader.streams_present()))
    if missing:
        raise CliError(f'calibration bag {bag} has no {" or ".join(missing)} stream: MLR is calibrated from '
                       '/imu/data_raw, /imu/mag and /imu/temperature')
    try:
        return MlrCalibration.fit(read_chunks(bag, 60.0), source=str(bag))
    except NotApplicable as exc:
        raise CliError(f'calibration bag {bag}: {exc}') from None


def evaluate_bag(path: Path, peers: bool = True, arw_deg_sqrt_s: float = 0.04, calibration=None, model_file=None,
                 source_options: dict | None = None):
    """Run every method over a recording (streamed; the whole-record MLR fit gets its own first pass) and
    score them. `calibration`: an `MlrCalibration` for `mlr` (else it is reported not applicable).
    `source_options`: open_source's (topic map, column map, IMU instance) for other formats."""
    from .evaluation.report import evaluate
    from .evaluation.suite import all_methods
    from .sources import open_source
    opts = source_options or {}
    with open_source(path, **opts) as source:
        present = source.streams_present()
        missing = {'imu', 'odom'} - set(present)
        if missing:
            raise CliError(f'{path} has no {" or ".join(sorted(missing))} stream: cannot evaluate '
                           f'(needs /imu/data_raw and /ground_truth/odom)')
        rate = source.rate_hz('imu')

    def chunks():
        with open_source(path, **opts) as again:
            yield from again.chunks(60.0)
    return evaluate(chunks, all_methods(rate, peers=peers, calibration=calibration, model_file=model_file),
                    arw_deg_sqrt_s=arw_deg_sqrt_s)


def cmd_evaluate(args) -> int:
    if not (args.arw > 0 and math.isfinite(args.arw)):
        raise CliError(f'--arw must be a positive number of deg/sqrt(s), got {args.arw}')
    opts = _source_options(args)
    if not _is_own_bag(args.bag, opts):
        from .sources import open_source
        with open_source(args.bag, **opts) as source:
            if not source.has_heading_truth:   # a flight log's attitude is fused from these same sensors
                print(f'{args.bag}: {source.label} without independent heading truth (no odom stream): '
                      'nothing to score')
                return 0
    if args.save_calibration and not args.calibration:
        raise CliError('--save-calibration FILE needs --calibration BAG')
    if args.save_calibration and not args.save_calibration.parent.is_dir():
        raise CliError(f'--save-calibration: folder {args.save_calibration.parent} does not exist')
    if args.calibration and args.calibration.resolve() == args.bag.resolve():
        raise CliError('--calibration must be another run than the bag evaluated (a fit to the evaluated '
                       'record itself is mlr_whole_record, the offline reference)')
    model_file = None
    if args.model is not None:   # before the calibration fit: a bad file is found at once
        from .thermal.model_file import DriftModelFile
        model_file = DriftModelFile.load(args.model)   # ValueError: one line naming the file
    calibration = mlr_calibration(args.calibration, args.calibration_file)
    if args.save_calibration:
        calibration.save(args.save_calibration)
        print(f'wrote {args.save_calibration}', file=sys.stderr)
    report = evaluate_bag(args.bag, peers=not args.no_peers, arw_deg_sqrt_s=args.arw, calibration=calibration,
                          model_file=model_file, source_options=opts)
    print(report.to_json() if args.json else report.to_text())
    if args.plots:
        from .evaluation.plots import save_plots
        args.plots.mkdir(parents=True, exist_ok=True)
        for path in save_plots(report, args.plots, prefix=args.bag.name + '_'):
            print(f'wrote {path}', file=sys.stderr)
    return 0


# ---------------------------------------------------------------- discover
def _add_discover(sub):
    p = sub.add_parser('discover', help='find where the drift model misses, name the missing effect, add it')
    p.add_argument('bag', type=Path)
    p.add_argument('--reference', choices=('static', 'odom'), default='static',
                   help='static: the unit did not move; odom: /ground_truth/odom gives the true rates')
    p.add_argument('--json', action='store_true', help='print the result as JSON')
    p.add_argument('--report', type=Path, metavar='DIR', help='write summary.md, discovery.json and figures')
    p.add_argument('--write-model', type=Path, metavar='FILE',
                   help='write the discovered drift model as a model file (stkf_node drift_model_file, '
                        'replay/evaluate --model)')
    _add_source_options(p)
    p.set_defaults(func=cmd_discover)


def cmd_discover(args) -> int:
    from .discrepancy import discover
    if args.report:
        args.report.mkdir(parents=True, exist_ok=True)
    if args.write_model is not None and not args.write_model.parent.is_dir():
        raise CliError(f'--write-model: folder {args.write_model.parent} does not exist')
    opts = _source_options(args)
    result = discover(args.bag if _is_own_bag(args.bag, opts) else _source_chunks(args.bag, opts),
                      reference=args.reference, report_dir=args.report)
    if args.write_model is not None:
        from .discrepancy.model_export import model_file_from_discovery
        model = model_file_from_discovery(result, str(args.bag)).save(args.write_model)
        print(f'wrote drift model {model}', file=sys.stderr)
    if args.json:
        print(result.to_json())
    else:
        d = result.to_dict()
        print(f'verdict: {d["verdict"]}; effects named in order: {", ".join(d["effects"]) or "none"}')
        if result.unexplained_reason:
            print(f'unexplained: {result.unexplained_reason}')
        print(f'residual RMS before/after (held out): {d["residual_rms_before"]} / {d["residual_rms_after"]}')
        print(f'heading error RMS before/after (held out): {d["heading_error_rms_before"]} / '
              f'{d["heading_error_rms_after"]}')
        print('candidate scores: ' + ', '.join(f'{k} {v:.3g}' if isinstance(v, (int, float)) else f'{k} -'
                                               for k, v in d['candidates'].items()))
        if args.report:
            print(f'report: {args.report / "summary.md"}')
    return 0


def _source_chunks(path: Path, opts: dict):
    """The chunks of any recording (sources.open_source), opened now: a bad file fails at once."""
    from .sources import open_source
    source = open_source(path, **opts)

    def chunks():
        with source:
            yield from source.chunks(60.0)
    return chunks()


# ---------------------------------------------------------------- replay
def _add_replay(sub):
    p = sub.add_parser('replay', help='run a node over a bag; write inputs + node outputs to a new bag')
    p.add_argument('bag', type=Path)
    p.add_argument('--out', type=Path, required=True, help='output bag folder')
    p.add_argument('--node', choices=('stkf', 'carousel'), default='stkf')
    p.add_argument('--params', type=Path, help='ROS parameter file (e.g. config/stkf.yaml)')
    p.add_argument('--live', action='store_true', help='publish over real DDS (loopback) into the node')
    p.add_argument('--rate', type=_positive, default=1.0, help='--live playback speed factor (default 1)')
    from .nodes.executors import EXECUTORS
    p.add_argument('--executor', choices=EXECUTORS, default='single',
                   help="--live: the node's rclpy executor (its --executor; default single)")
    p.add_argument('--duration', type=_positive, help='replay only the first S seconds')
    p.add_argument('--start', dest='start_s', type=_non_negative, default=0.0, metavar='SECONDS',
                   help='begin this far into the bag: the node starts there (a restart on the move)')
    p.add_argument('--force', action='store_true', help='overwrite an existing output bag')
    p.add_argument('--model', type=Path, metavar='FILE',
                   help='drift model file for the stkf node (discover --write-model; its drift_model_file parameter)')
    _add_source_options(p)
    p.set_defaults(func=cmd_replay)


def cmd_replay(args) -> int:
    from .nodes.replay import replay
    from .nodes.ros_params import ParameterFileError
    from .sources.importer import package_bag
    summary: list[str] = []
    if args.out.exists() and not args.force:   # before the recording is read (an import may take minutes)
        raise CliError(f'output bag {args.out} already exists (use --force to overwrite)')
    try:
        with package_bag(args.bag, **_source_options(args)) as (bag, topic_map, imported):
            if imported is not None:   # what was read, as `import` says it
                print('\n'.join([imported.description, *(f'  {n}' for n in imported.notes), f'  {imported.dropped}']))
            counts = replay(bag, args.out, node=args.node, params_file=args.params, live=args.live,
                            rate=args.rate, duration_s=args.duration, overwrite=args.force, model_file=args.model,
                            executor=args.executor, topic_map=topic_map, start_s=args.start_s, summary=summary)
    except ParameterFileError as exc:
        raise CliError(str(exc)) from None
    print(f'wrote {args.out}: ' + ', '.join(f'{t} {n}' for t, n in counts.items()))
    for line in summary:   # the stkf node: its updates, or why it learned nothing
        print(line)
    return 0


# ---------------------------------------------------------------- import
def _add_import(sub):
    p = sub.add_parser('import', help='convert a recording (ROS 1/2 bag, PX4 ULog, ArduPilot log, CSV/netCDF/HDF5) '
                                      "into rosbag2 with the package's topics")
    p.add_argument('source', type=Path, metavar='SRC')
    p.add_argument('--out', type=Path, required=True, metavar='DIR',
                   help='output bag folder (with --split-static: a folder of bags period_1, period_2, ...)')
    _add_source_options(p, window=True)
    p.add_argument('--level', action='store_true',
                   help='rotate the record so that its rest orientation puts the vertical on +z')
    p.add_argument('--split-static', action='store_true',
                   help='one bag per static period (where the orientation changes), each levelled')
    p.add_argument('--min-static', type=_positive, default=600.0, metavar='S',
                   help='--split-static: shortest static period kept, s (default 600)')
    p.add_argument('--force', action='store_true', help='overwrite an existing output')
    p.set_defaults(func=cmd_import)


def cmd_import(args) -> int:
    from .sources.importer import import_recording
    result = import_recording(args.source, args.out, level=args.level, split_static=args.split_static,
                              min_static_s=args.min_static, overwrite=args.force, **_source_options(args))
    print(result.to_text())
    return 0


# ---------------------------------------------------------------- calibrate
def _add_calibrate(sub):
    p = sub.add_parser('calibrate', help='bench calibration from warm-up or drive logs: drift model file, warm-start '
                                         'state and a report per unit')
    p.add_argument('logs', nargs='+', type=Path, metavar='LOG')
    p.add_argument('--out', type=Path, required=True, metavar='DIR',
                   help='output folder (with --unit: one sub-folder per unit)')
    p.add_argument('--unit', metavar='PATTERN',
                   help='the unit of each log: a regular expression on its file name (first group), or field:NAME '
                        '(a field the log carries, e.g. field:sys_uuid, field:param.INS_GYR_ID)')
    p.add_argument('--reference', choices=('auto', 'static', 'odom', 'compass'), default='auto',
                   help='what gives the true rate (default auto: odom if present, else static if the unit rests, '
                        'else the compass through the STKF)')
    p.add_argument('--jobs', type=int, metavar='N', help='processes on this machine (default: one per unit, '
                                                         'at most one per core)')
    p.add_argument('--scheduler', metavar='ADDRESS', help='run on this Dask distributed scheduler (tcp://host:8786)')
    _add_source_options(p)
    p.add_argument('--force', action='store_true', help='overwrite existing outputs')
    p.set_defaults(func=cmd_calibrate)


def cmd_calibrate(args) -> int:
    from .calibration import calibrate_fleet
    if args.jobs is not None and args.jobs < 1:
        raise CliError('--jobs must be at least 1')
    opts = _source_options(args)
    outcomes = calibrate_fleet(args.logs, args.out, unit=args.unit, source_options=opts, reference=args.reference,
                               jobs=args.jobs, scheduler=args.scheduler, overwrite=args.force)
    failed = [o for o in outcomes if o.error]
    for o in outcomes:
        if o.error is None:
            print(f'unit {o.unit}: {len(o.logs)} log(s) -> {o.folder} ({", ".join(o.calibration.state["terms"])})')
    for o in failed:
        print(f'{PROG}: error: unit {o.unit}: {o.error}', file=sys.stderr)
    return EXIT_BAD_INPUT if failed else 0


# ---------------------------------------------------------------- params
def _add_params(sub):
    p = sub.add_parser('params', help='print (or --write) the default node parameter files')
    p.add_argument('--write', type=Path, metavar='DIR', help='write the files (stkf.yaml, carousel*.yaml) into DIR')
    p.set_defaults(func=cmd_params)


def default_param_files() -> dict[str, str]:
    from .carousel import CarouselConfig
    from .nodes.carousel_node import NODE_NAME as CAROUSEL, carousel_specs
    from .nodes.parameters import STKF_FILE_SECTIONS, all_specs, params_yaml
    from .nodes.stkf_node import NODE_NAME as STKF
    return {'stkf.yaml': params_yaml(STKF, all_specs(), 'stkf_node', 'stkf.yaml', STKF_FILE_SECTIONS),
            'carousel.yaml': params_yaml(CAROUSEL, carousel_specs(), 'carousel_node', 'carousel.yaml'),
            'carousel_wheel.yaml': params_yaml(CAROUSEL, carousel_specs(CarouselConfig.wheel()), 'carousel_node',
                                               'carousel_wheel.yaml')}


def cmd_params(args) -> int:
    for name, text in default_param_files().items():
        if args.write:
            if not args.write.is_dir():
                raise CliError(f'{args.write} is not a folder')
            (args.write / name).write_text(text)
            print(f'wrote {args.write / name}')
        else:
            print(f'# ---- {name}\n{text}')
    return 0


# ---------------------------------------------------------------- entry point
def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument('--debug', action='store_true', help='show tracebacks for unexpected errors')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    for add in (_add_simulate, _add_info, _add_bundle, _add_demo, _add_evaluate, _add_discover, _add_replay,
                _add_import, _add_calibrate, _add_params):
        add(sub)
    return parser


def _one_line_bag_warnings(original):
    """A `warnings.showwarning` that prints BagWarnings as `PROG: warning: <message>`, each text
    once (no source line, no category); other warnings go to `original`."""
    from .bag_io import BagWarning
    seen = set()

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, BagWarning):
            return original(message, category, filename, lineno, file, line)
        text = ' '.join(str(message).split())
        if text not in seen:
            seen.add(text)
            print(f'{PROG}: warning: {text}', file=sys.stderr if file is None else file)
    return show


def main(argv=None) -> int:
    from .bag_io import BagError
    argv = sys.argv[1:] if argv is None else argv
    debug = '--debug' in argv
    with warnings.catch_warnings():  # restores the caller's warning set-up when main returns
        warnings.showwarning = _one_line_bag_warnings(warnings.showwarning)
        try:
            args = build_parser().parse_args(argv)
            if not getattr(args, 'func', None):
                raise CliError('missing COMMAND (simulate, info, bundle, demo, params, ...); see --help')
            return args.func(args)
        except (CliError, BagError, ValueError, OSError) as exc:
            print(f'{PROG}: error: {_one_line(exc)}', file=sys.stderr)
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:
            print(f'{PROG}: interrupted', file=sys.stderr)
            return 130
        except Exception as exc:  # a bug, not bad input: still one line unless --debug
            if debug:
                raise
            print(f'{PROG}: internal error: {type(exc).__name__}: {_one_line(exc)} (rerun with --debug)',
                  file=sys.stderr)
            return 1


def _one_line(exc) -> str:
    return ' '.join(str(exc).split()) or type(exc).__name__


if __name__ == '__main__':
    sys.exit(main())
